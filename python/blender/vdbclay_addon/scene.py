"""The scene the add-on writes for `vdbclay run`, from plain data (no bpy: testable anywhere).

The scene is in world units, z up ("units": "world", "up": "z"): Blender's coordinates as they are.
Every marked object's mesh is written as an OBJ in world coordinates at the first frame; a tool's
keyframed motion over the frame range becomes one path segment per frame, relative to that pose,
turning about the tool's origin (docs/SCENES.md, World units).
"""
import json
import math

ROLES = ("NONE", "CLAY", "TOOL", "OBSTACLE")


def write_obj(path, vertices, triangles, comment=""):
    """Writes an OBJ of world-space @a vertices ((x, y, z) tuples) and @a triangles (index triples)."""
    with open(path, "w") as f:
        f.write("# vdbclay Blender add-on: %s (world units, z up)\n" % comment)
        for v in vertices:
            f.write("v %r %r %r\n" % (float(v[0]), float(v[1]), float(v[2])))
        for t in triangles:
            f.write("f %d %d %d\n" % (t[0] + 1, t[1] + 1, t[2] + 1))


def tool_path(poses, pivot):
    """One path segment per frame from the tool's poses.

    poses: for frames 0..N, (translation, euler_deg): the tool's motion relative to frame 0 as a
    turn (XYZ Euler degrees, about x first, as Blender's 'XYZ' order) about @a pivot followed by a
    translation, both in world units. Segment k moves from pose k to pose k + 1.
    """
    path = []
    for k in range(1, len(poses)):
        (t0, e0), (t1, e1) = poses[k - 1], poses[k]
        path.append({"translate": [t1[i] - t0[i] for i in range(3)],
                     "rotate": [e1[i] - e0[i] for i in range(3)]})
    if not path:
        raise ValueError("a tool needs at least two frames of motion")
    return path


def scene_dict(settings, clay, tools, obstacles, frames, description=""):
    """The scene as a dict (json.dump writes it).

    settings: voxel_size, threshold, rule, push, transport. clay: [(obj_file, mass)];
    tools: [(obj_file, pivot, path)]; obstacles: [obj_file]; frames: the run's frame count.
    """
    if frames < 1:
        raise ValueError("the frame range holds no frame after the first (set End after Start)")
    if not clay:
        raise ValueError("no object is marked as clay")
    scene = {
        "description": description or "written by the vdbclay Blender add-on",
        "units": "world",
        "up": "z",
        # Blender's float properties are 32-bit: 0.1 is written 0.1, not 0.10000000149011612.
        "voxel_size": float("%.7g" % settings["voxel_size"]),
        "threshold": int(settings["threshold"]),
        "rule": settings["rule"],
        "push": settings["push"],
        "transport": settings["transport"],
        "frames": int(frames),
        "clay": [{"shape": "mesh", "file": f, "mass": int(m)} for f, m in clay],
        "tools": [{"shape": "mesh", "file": f, "pivot": [float(c) for c in pivot], "path": path}
                  for f, pivot, path in tools],
        "obstacles": [{"shape": "mesh", "file": f} for f in obstacles],
        "outputs": {"vdb": "clay.####.vdb"},
    }
    return scene


def write_scene(path, scene):
    with open(path, "w") as f:
        json.dump(scene, f, indent=1)
        f.write("\n")


def first_frame_file(out_dir, frame=1):
    """The sequence's file for vdbclay frame @a frame (clay.0001.vdb)."""
    import os
    return os.path.join(out_dir, "clay.%04d.vdb" % frame)


def parse_progress(line):
    """(frame, total) from a `vdbclay run` progress line ("frame 3/10: pushed ..."), else None."""
    if not line.startswith("frame "):
        return None
    head = line[6:].split(":", 1)[0]
    if "/" not in head:
        return None
    a, b = head.split("/", 1)
    try:
        return int(a), int(b)
    except ValueError:
        return None


def degrees(euler):
    return [math.degrees(a) for a in euler]
