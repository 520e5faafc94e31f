"""The screenshot's scene (scripts/blender-screenshot.sh): the add-on installed, the factory cube
squashed as clay, an animated sphere as a tool, a slab as an obstacle, saved as a .blend."""
import sys, bpy, addon_utils
argv = sys.argv[sys.argv.index("--") + 1:]
zip_path, blend = argv
bpy.ops.preferences.addon_install(filepath=zip_path, overwrite=True)
addon_utils.enable("vdbclay_addon", default_set=True)
scn = bpy.context.scene
cube = bpy.data.objects["Cube"]
cube.scale = (1.0, 0.6, 0.5)
cube.vdbclay.role = "CLAY"
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(0.0, 0.0, 1.0))
tool = bpy.context.active_object
tool.name = "Tool"
tool.vdbclay.role = "TOOL"
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, -0.65), scale=(3.0, 3.0, 0.2))
floor = bpy.context.active_object
floor.name = "Floor"
floor.vdbclay.role = "OBSTACLE"
scn.frame_start, scn.frame_end = 1, 5
for frame, z in ((1, 1.0), (5, 0.55)):
    tool.location.z = z
    tool.keyframe_insert("location", frame=frame)
s = scn.vdbclay
s.voxel_size = 0.1
s.output = "//vdbclay/"
s.executable = ""  # found on PATH
for o in scn.objects:
    o.select_set(False)
bpy.context.view_layer.objects.active = cube
cube.select_set(True)
bpy.ops.wm.save_as_mainfile(filepath=blend)
