"""The Blender add-on's scene writer (python/blender/vdbclay_addon/scene.py: no bpy), and the scene
it writes run through the vdbclay module: world units, z up, one path segment per frame."""
import importlib.util
import json
import os
import tempfile
import unittest

import vdbclay

_HERE = os.path.dirname(os.path.abspath(__file__))
_spec = importlib.util.spec_from_file_location(
    "vdbclay_addon_scene", os.path.join(_HERE, "..", "blender", "vdbclay_addon", "scene.py"))
vscene = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(vscene)

SETTINGS = {"voxel_size": 0.1, "threshold": 1000, "rule": "prorata", "push": "surface", "transport": "local"}
CUBE = [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]
CUBE_TRIS = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4), (1, 2, 6), (1, 6, 5),
             (2, 3, 7), (2, 7, 6), (3, 0, 4), (3, 4, 7)]


class BlenderScene(unittest.TestCase):
    def test_tool_path_is_one_segment_per_frame(self):
        poses = [([0, 0, 0], [0, 0, 0]), ([0, 0, -0.1], [0, 0, 10]), ([0.5, 0, -0.3], [5, 0, 25])]
        path = vscene.tool_path(poses, [0, 0, 1])
        self.assertEqual(len(path), 2)
        self.assertEqual(path[1]["translate"], [0.5, 0, -0.19999999999999998])
        self.assertEqual(path[1]["rotate"], [5, 0, 15])
        with self.assertRaises(ValueError):
            vscene.tool_path(poses[:1], [0, 0, 0])

    def test_progress_lines(self):
        self.assertEqual(vscene.parse_progress("frame 3/10: pushed 5 voxels"), (3, 10))
        self.assertIsNone(vscene.parse_progress("frames 10, steps 5"))
        self.assertIsNone(vscene.parse_progress("wrote clay.0001.vdb"))

    def test_scene_refusals(self):
        with self.assertRaisesRegex(ValueError, "no object is marked as clay"):
            vscene.scene_dict(SETTINGS, [], [], [], 4)
        with self.assertRaisesRegex(ValueError, "frame range"):
            vscene.scene_dict(SETTINGS, [("c.obj", 800)], [], [], 0)

    def test_the_written_scene_runs(self):
        # A 2 m cube of clay and a box tool coming down 0.1 m a frame for 3 frames, z up: the run
        # keeps the cube's 20^3 voxels x 800 and presses it.
        with tempfile.TemporaryDirectory() as d:
            vscene.write_obj(os.path.join(d, "clay.obj"), CUBE, CUBE_TRIS, "clay Cube")
            tool = [(x * 0.5, y * 0.5, z * 0.25 + 1.1) for x, y, z in CUBE]
            vscene.write_obj(os.path.join(d, "tool.obj"), tool, CUBE_TRIS, "tool Box")
            poses = [([0, 0, -0.1 * k], [0, 0, 5 * k]) for k in range(4)]
            sc = vscene.scene_dict(SETTINGS, [("clay.obj", 800)],
                                   [("tool.obj", [0, 0, 1.1], vscene.tool_path(poses, [0, 0, 1.1]))], [], 3)
            vscene.write_scene(os.path.join(d, "scene.json"), sc)
            with open(os.path.join(d, "scene.json")) as f:
                self.assertEqual(json.load(f)["outputs"], {"vdb": "clay.####.vdb"})
            scene = vdbclay.Scene.load(os.path.join(d, "scene.json"))
            s = vdbclay.Sculptor(scene, threads=2)
            report = s.run()
            self.assertEqual(report["mass_initial"], 20 ** 3 * 800)
            self.assertEqual(report["mass_final"], 20 ** 3 * 800)
            self.assertGreater(report["frames"], 0)


if __name__ == "__main__":
    unittest.main()
