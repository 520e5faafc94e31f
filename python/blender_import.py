"""Runs a vdbclay scene from Blender's Python and loads the result, upright, as a volume and a mesh.

    blender --python python/blender_import.py -- --scene data/scenes/paper/cube-big-plate.json --out /tmp/clay
    blender -b --python python/blender_import.py -- --scene SCENE.json --out DIR      # headless

Debian's Blender runs on the system Python, so the `vdbclay` module built for /usr/bin/python3
imports here (put its folder on PYTHONPATH, or `cmake --install` it). Without a scene, the built-in
default scene runs. The clay is written with up = z (Blender's up), so the volume's transform
stands it upright; the OBJ is in the same world coordinates and is imported with Z up, Y forward
(i.e. without Blender's default y-up conversion), so it lies exactly on the volume.
"""
import argparse
import os
import sys

import bpy
import vdbclay

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
ap = argparse.ArgumentParser(prog="blender_import.py")
ap.add_argument("--scene", help="scene .json (default: the built-in scene)")
ap.add_argument("--out", default=os.path.join(os.getcwd(), "vdbclay-blender"), help="output folder")
ap.add_argument("--frames", type=int, default=0, help="frames to run (0: all)")
args = ap.parse_args(argv)
os.makedirs(args.out, exist_ok=True)

scene = vdbclay.Scene.load(args.scene) if args.scene else vdbclay.Scene.default()
sculptor = vdbclay.Sculptor(scene)
sculptor.run(frames=args.frames,
             progress=lambda r: print(f"vdbclay: frame {r['frame']}/{r['total_frames']}", flush=True))

clay = sculptor.clay
clay.up = "z"  # the file's transform turns vdbclay's y-up index space into Blender's z-up world
vdb_path = os.path.join(args.out, "clay.vdb")
obj_path = os.path.join(args.out, "clay.obj")
clay.write(vdb_path)
clay.write_mesh(obj_path)

bpy.ops.object.volume_import(filepath=vdb_path, files=[{"name": os.path.basename(vdb_path)}])
volume = bpy.context.selected_objects[0]
if hasattr(bpy.ops.wm, "obj_import"):  # Blender 3.2+
    bpy.ops.wm.obj_import(filepath=obj_path, forward_axis="Y", up_axis="Z")
else:
    bpy.ops.import_scene.obj(filepath=obj_path, axis_forward="Y", axis_up="Z")
mesh = bpy.context.selected_objects[0]

# Both must stand on the same box: the volume's grids and the mesh in world space.
zs = [(mesh.matrix_world @ v.co).z for v in mesh.data.vertices]
lo, hi = clay.bounds
expect_top = (hi[1] + 0.5) * clay.voxel_size
print(f"vdbclay-blender: mesh z {min(zs):.3f}..{max(zs):.3f}, clay top {expect_top:.3f}")
assert abs(max(zs) - expect_top) < clay.voxel_size, "the mesh is not upright"
print("vdbclay-blender: ok")
