"""The vdbclay add-on in a headless Blender (tests/blender/addon.sh runs it): the factory cube,
squashed, as clay; an animated sphere as a tool; a floor as an obstacle; the Run operator to the
end; then the VDB sequence checked: one file per frame, the exact mass in each, upright bounds in
world units, the Volume object playing it, and the saved scene rerun by the CLI to the same clay.

    blender -b --factory-startup --python-exit-code 1 --python addon_test.py -- --cli VDBCLAY --out DIR
"""
import argparse
import os
import re
import subprocess
import sys

import addon_utils
import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
ap = argparse.ArgumentParser()
ap.add_argument("--cli", required=True)
ap.add_argument("--out", required=True)
ap.add_argument("--zip", required=True)
args = ap.parse_args(argv)

bpy.ops.preferences.addon_install(filepath=args.zip, overwrite=True)
addon_utils.enable("vdbclay_addon", default_set=True, handle_error=None)
assert hasattr(bpy.types.Scene, "vdbclay"), "the add-on did not register"
assert hasattr(bpy.ops.vdbclay, "run") and hasattr(bpy.ops.vdbclay, "mark")

scn = bpy.context.scene
for o in list(scn.objects):
    if o.type != "MESH":
        bpy.data.objects.remove(o)
cube = bpy.data.objects["Cube"]  # 2 m at the origin
cube.scale = (1.0, 0.6, 0.5)    # x +-1, y +-0.6, z +-0.5: a wrong up axis would show in the bounds
cube.vdbclay.role = "CLAY"
cube.vdbclay.mass = 800
bpy.ops.mesh.primitive_uv_sphere_add(radius=0.4, location=(0.0, 0.0, 1.0))
tool = bpy.context.active_object
tool.name = "Tool"
scn.frame_start, scn.frame_end = 1, 5
for frame, z in ((1, 1.0), (5, 0.55)):
    tool.location.z = z
    tool.keyframe_insert("location", frame=frame)
bpy.ops.object.select_all(action="DESELECT")
tool.select_set(True)
bpy.ops.vdbclay.mark(role="TOOL")
assert tool.vdbclay.role == "TOOL"
bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, -0.65), scale=(3.0, 3.0, 0.2))
floor = bpy.context.active_object
floor.vdbclay.role = "OBSTACLE"

s = scn.vdbclay
s.voxel_size = 0.1
s.threshold = 1000
s.output = args.out
s.executable = args.cli
assert bpy.ops.vdbclay.run() == {"FINISHED"}

# One file per frame (4 frames after the first), the scene and meshes beside them.
names = sorted(n for n in os.listdir(args.out) if n.endswith(".vdb"))
assert names == ["clay.0001.vdb", "clay.0002.vdb", "clay.0003.vdb", "clay.0004.vdb"], names
assert os.path.exists(os.path.join(args.out, "scene.json"))


def info(path):
    return subprocess.run([args.cli, "info", path], check=True, capture_output=True, text=True).stdout


def first(pattern, text):
    m = re.search(pattern, text, re.M)
    assert m, pattern
    return m.group(1)


# The cube's 2 x 1.2 x 1 m at 0.1 m per voxel: 2400 voxels of volume, 800 each, in every frame.
for n in names:
    mass = int(first(r"^  total mass: (\d+)$", info(os.path.join(args.out, n))))
    assert mass == 2400 * 800, (n, mass)
# Upright, in world units: frame 1 (the tool has not reached the clay) lies on the cube, z up.
bounds = first(r"^  world bounds: (.*) \(the outer", info(os.path.join(args.out, "clay.0001.vdb")))
nums = [float(x) for x in re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", bounds)]
expect = [-1.05, -0.65, -0.55, 1.05, 0.65, 0.55]
assert all(abs(a - b) < 1e-6 for a, b in zip(nums, expect)), bounds
# The tool pressed the clay: the last frame is other clay than the first, its top lower.
last = info(os.path.join(args.out, "clay.0004.vdb"))
assert first(r"content hash: ([0-9a-f]+)", last) != first(r"content hash: ([0-9a-f]+)", info(os.path.join(args.out, "clay.0001.vdb")))
# The Volume object plays the sequence from Blender's frame 2 (vdbclay's frame 1).
vol = bpy.data.objects["vdbclay"]
assert vol.type == "VOLUME"
assert vol.data.is_sequence and vol.data.frame_duration == 4 and vol.data.frame_start == 2, (
    vol.data.is_sequence, vol.data.frame_duration, vol.data.frame_start)
assert os.path.basename(vol.data.filepath) == "clay.0001.vdb", vol.data.filepath
# The saved scene reruns from the CLI to the same clay.
subprocess.run([args.cli, "run", "scene.json", "--quiet", "-o", "rerun.vdb"], cwd=args.out, check=True)
assert first(r"content hash: ([0-9a-f]+)", info(os.path.join(args.out, "rerun.vdb"))) == first(r"content hash: ([0-9a-f]+)", last)
# A tool whose scale is animated is refused, naming it; nothing is run.
tool.scale = (1.0, 1.0, 1.0)
tool.keyframe_insert("scale", frame=1)
tool.scale = (2.0, 2.0, 2.0)
tool.keyframe_insert("scale", frame=5)
try:
    bpy.ops.vdbclay.run()
    raise AssertionError("a tool with an animated scale was run")
except RuntimeError as e:
    assert "tool 'Tool' changes its scale at frame 2" in str(e), str(e)
print("vdbclay-addon: ok")
