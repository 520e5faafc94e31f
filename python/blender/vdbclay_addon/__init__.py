"""vdbclay for Blender: sculpt virtual clay with keyframed tools, and play the result.

In the 3D view's sidebar (N), tab vdbclay: mark mesh objects as clay (with a mass per voxel), tools
(their keyframed motion over the scene's frame range is the tool's path; their mesh its shape) or
obstacles; set the voxel size, Tc, rule, push and transport; Run. The run writes, in the output
folder, the scene (scene.json, in world units: `vdbclay run scene.json` reruns it), the objects'
meshes (meshes/*.obj) and the clay after every frame (clay.0001.vdb, ...), in the background with
Blender's progress bar (Esc cancels: the frames written so far stay), then loads the sequence as a
Volume object that plays with the timeline.

Operators: vdbclay.mark (role of the selected objects), vdbclay.export_scene (the scene and meshes
only), vdbclay.run (invoke: in the background; execute, e.g. from a script or `blender -b`: waits),
vdbclay.load_sequence (the sequence in the output folder as a Volume object).
"""

bl_info = {
    "name": "vdbclay",
    "author": "vdbclay",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > vdbclay",
    "description": "Virtual clay: mark clay, tools and obstacles, run vdbclay, play the VDB sequence",
    "doc_url": "https://github.com/vdbclay/vdbclay/blob/main/docs/INTEROP.md",
    "category": "Object",
}

import os
import queue
import re
import shutil
import signal
import subprocess
import threading

import bpy

from . import scene as vscene

RULES = [("prorata", "Pro rata", "Rule 3: every neighbour under Tc takes a share (the default)"),
         ("sorted", "Sorted", "Rule 2: the emptiest neighbours first"),
         ("bingham", "Bingham", "Rule 1: a yield stress"),
         ("arata", "Arata", "Arata's rate alpha")]
PUSHES = [("surface", "Surface", "The paper's push: clay a tool enters goes just past its surface"),
          ("compress", "Compress", "Spread over the clay ahead of the tool (nearly incompressible clay)")]
TRANSPORTS = [("local", "Local", "The paper's automaton alone"),
              ("global", "Global", "A pressure projection each frame moves the overload through full clay")]
ROLE_ITEMS = [("NONE", "None", "Not part of the sculpture"),
              ("CLAY", "Clay", "Clay: its volume fills with clay"),
              ("TOOL", "Tool", "A tool: its keyframed motion pushes the clay"),
              ("OBSTACLE", "Obstacle", "A static obstacle the clay never enters")]


class VdbclayObjectSettings(bpy.types.PropertyGroup):
    role: bpy.props.EnumProperty(name="Role", items=ROLE_ITEMS, default="NONE")
    mass: bpy.props.IntProperty(name="Mass", description="Clay per voxel (Tc is a full cell)",
                                default=800, min=1)


class VdbclaySceneSettings(bpy.types.PropertyGroup):
    voxel_size: bpy.props.FloatProperty(name="Voxel size", description="World units per voxel",
                                        default=0.05, min=1e-4, max=1e6, precision=4)
    threshold: bpy.props.IntProperty(name="Tc", description="The mass of a full cell",
                                     default=1000, min=1)
    rule: bpy.props.EnumProperty(name="Rule", items=RULES, default="prorata")
    push: bpy.props.EnumProperty(name="Push", items=PUSHES, default="surface")
    transport: bpy.props.EnumProperty(name="Transport", items=TRANSPORTS, default="local")
    output: bpy.props.StringProperty(name="Output", subtype="DIR_PATH", default="//vdbclay/",
                                     description="Folder for the scene, its meshes and the VDB sequence")
    executable: bpy.props.StringProperty(name="vdbclay", subtype="FILE_PATH", default="",
                                         description="The vdbclay program (empty: found on PATH)")
    threads: bpy.props.IntProperty(name="Threads", description="0: all cores", default=0, min=0, max=256)
    running: bpy.props.BoolProperty(default=False)
    progress: bpy.props.StringProperty(default="")


def _settings(context):
    return context.scene.vdbclay


def _output_dir(context):
    path = bpy.path.abspath(_settings(context).output or "//vdbclay/")
    if not path or path.startswith("//"):
        raise RuntimeError("save the .blend file first, or give an absolute output folder")
    return os.path.abspath(path)


def _executable(context):
    exe = _settings(context).executable
    if exe:
        exe = bpy.path.abspath(exe)
        if not os.access(exe, os.X_OK):
            raise RuntimeError("vdbclay program %r is not executable" % exe)
        return exe
    found = shutil.which("vdbclay")
    if found:
        return found
    raise RuntimeError("no vdbclay program on PATH; set its path in the vdbclay panel")


def _marked(context, role):
    return [o for o in context.scene.objects if o.type == "MESH" and o.vdbclay.role == role]


def _world_mesh(obj, depsgraph):
    """The evaluated mesh of @a obj in world coordinates: (vertices, triangles)."""
    ev = obj.evaluated_get(depsgraph)
    me = ev.to_mesh()
    try:
        me.calc_loop_triangles()
        m = ev.matrix_world
        verts = [tuple(m @ v.co) for v in me.vertices]
        tris = [tuple(t.vertices) for t in me.loop_triangles]
    finally:
        ev.to_mesh_clear()
    if not tris:
        raise RuntimeError("object %r has no faces" % obj.name)
    return verts, tris


def _safe_name(name):
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name) or "object"


def export_scene(context, out_dir):
    """Writes out_dir/meshes/*.obj and out_dir/scene.json; returns the scene's frame count."""
    scn = context.scene
    s = _settings(context)
    start, end = scn.frame_start, scn.frame_end
    frames = end - start
    os.makedirs(os.path.join(out_dir, "meshes"), exist_ok=True)
    current = scn.frame_current
    try:
        scn.frame_set(start)
        depsgraph = context.evaluated_depsgraph_get()

        def mesh_file(obj, role):
            verts, tris = _world_mesh(obj, depsgraph)
            rel = "meshes/%s-%s.obj" % (role.lower(), _safe_name(obj.name))
            vscene.write_obj(os.path.join(out_dir, rel), verts, tris, "%s %s" % (role.lower(), obj.name))
            return rel

        clay = [(mesh_file(o, "CLAY"), o.vdbclay.mass) for o in _marked(context, "CLAY")]
        obstacles = [mesh_file(o, "OBSTACLE") for o in _marked(context, "OBSTACLE")]
        tools = []
        starts = {}
        for o in _marked(context, "TOOL"):
            tools.append([mesh_file(o, "TOOL"), None, None, o])
            starts[o.name] = o.matrix_world.copy()
        # The tools' poses at every frame, relative to the first: a turn about the origin, then a move.
        poses = {o.name: [] for *_, o in tools}
        eulers = {}
        for f in range(start, end + 1):
            scn.frame_set(f)
            for *_, o in tools:
                m0 = starts[o.name]
                delta = o.matrix_world @ m0.inverted()
                if any(abs(k - 1.0) > 1e-4 for k in delta.to_scale()):
                    raise RuntimeError("tool %r changes its scale at frame %d; vdbclay moves a tool without "
                                       "scaling it (its scale is the first frame's)" % (o.name, f))
                rot = delta.to_3x3().normalized()
                origin = m0.translation
                moved = delta @ origin
                prev = eulers.get(o.name)
                e = rot.to_euler("XYZ", prev) if prev is not None else rot.to_euler("XYZ")
                eulers[o.name] = e
                poses[o.name].append(([moved[i] - origin[i] for i in range(3)], vscene.degrees(e)))
        for t in tools:
            o = t[3]
            t[1] = list(starts[o.name].translation)
            t[2] = vscene.tool_path(poses[o.name], t[1])
    finally:
        scn.frame_set(current)
    settings = {"voxel_size": s.voxel_size, "threshold": s.threshold, "rule": s.rule, "push": s.push,
                "transport": s.transport}
    desc = "written by the vdbclay Blender add-on from %s, frames %d..%d" % (
        bpy.path.basename(bpy.data.filepath) or "an unsaved file", start, end)
    sc = vscene.scene_dict(settings, clay, [(f, p, path) for f, p, path, _ in tools], obstacles, frames, desc)
    vscene.write_scene(os.path.join(out_dir, "scene.json"), sc)
    return frames


def _clear_sequence(out_dir):
    for name in os.listdir(out_dir):
        if re.fullmatch(r"clay\.\d{4,}\.vdb", name) or name == "clay.checkpoint.vdb":
            os.remove(os.path.join(out_dir, name))


def _command(context, out_dir):
    cmd = [_executable(context), "run", "scene.json"]
    if _settings(context).threads:
        cmd += ["--threads", str(_settings(context).threads)]
    return cmd


def load_sequence(context, out_dir, frames):
    """The VDB sequence as a Volume object named vdbclay (replacing an earlier one's data)."""
    first = vscene.first_frame_file(out_dir, 1)
    if not os.path.exists(first):
        raise RuntimeError("no %s: nothing to load" % first)
    vol = bpy.data.volumes.new("vdbclay")
    vol.filepath = first
    vol.is_sequence = frames > 1
    vol.frame_duration = frames
    vol.frame_start = context.scene.frame_start + 1  # vdbclay's frame 1 is Blender's first frame + 1
    vol.frame_offset = 0
    vol.sequence_mode = "EXTEND"
    obj = bpy.data.objects.get("vdbclay")
    if obj is not None and obj.type == "VOLUME":
        old = obj.data
        obj.data = vol
        if old.users == 0:
            bpy.data.volumes.remove(old)
    else:
        obj = bpy.data.objects.new("vdbclay", vol)
        context.scene.collection.objects.link(obj)
    return obj


class _Run:
    """A vdbclay run in a child process, its stdout read by a thread into a queue."""

    def __init__(self, cmd, cwd):
        self.proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, start_new_session=True)
        self.lines = queue.Queue()
        self.err = []
        self.frame = 0
        threading.Thread(target=self._read, args=(self.proc.stdout, self.lines), daemon=True).start()
        threading.Thread(target=self._read, args=(self.proc.stderr, None), daemon=True).start()

    def _read(self, stream, q):
        for line in stream:
            if q is not None:
                q.put(line.rstrip("\n"))
            else:
                self.err.append(line.rstrip("\n"))

    def poll(self):
        """Progress so far: (frame, total) of the latest line, or None."""
        latest = None
        while True:
            try:
                line = self.lines.get_nowait()
            except queue.Empty:
                return latest
            p = vscene.parse_progress(line)
            if p:
                latest = p
                self.frame = p[0]

    def error(self):
        return self.err[-1] if self.err else "exit status %s" % self.proc.returncode


class VDBCLAY_OT_mark(bpy.types.Operator):
    """Mark the selected mesh objects as clay, tools, obstacles, or none"""
    bl_idname = "vdbclay.mark"
    bl_label = "Mark"
    bl_options = {"REGISTER", "UNDO"}

    role: bpy.props.EnumProperty(name="Role", items=ROLE_ITEMS)

    @classmethod
    def poll(cls, context):
        return any(o.type == "MESH" for o in context.selected_objects)

    def execute(self, context):
        n = 0
        for o in context.selected_objects:
            if o.type == "MESH":
                o.vdbclay.role = self.role
                n += 1
        self.report({"INFO"}, "%d objects marked %s" % (n, self.role.lower()))
        return {"FINISHED"}


class VDBCLAY_OT_export_scene(bpy.types.Operator):
    """Write the scene (scene.json) and the marked objects' meshes to the output folder"""
    bl_idname = "vdbclay.export_scene"
    bl_label = "Export Scene"

    def execute(self, context):
        try:
            out = _output_dir(context)
            export_scene(context, out)
        except (RuntimeError, ValueError, OSError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self.report({"INFO"}, "wrote %s" % os.path.join(out, "scene.json"))
        return {"FINISHED"}


class VDBCLAY_OT_load_sequence(bpy.types.Operator):
    """Load the VDB sequence of the output folder as a Volume object"""
    bl_idname = "vdbclay.load_sequence"
    bl_label = "Load Sequence"

    def execute(self, context):
        try:
            out = _output_dir(context)
            frames = len([n for n in os.listdir(out) if re.fullmatch(r"clay\.\d{4,}\.vdb", n)])
            load_sequence(context, out, frames)
        except (RuntimeError, OSError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return {"FINISHED"}


class VDBCLAY_OT_run(bpy.types.Operator):
    """Run vdbclay on the marked objects over the frame range and load the VDB sequence (Esc cancels)"""
    bl_idname = "vdbclay.run"
    bl_label = "Run"

    _run = None
    _timer = None

    @classmethod
    def poll(cls, context):
        return not _settings(context).running

    def _start(self, context):
        self.out = _output_dir(context)
        os.makedirs(self.out, exist_ok=True)
        self.frames = export_scene(context, self.out)
        _clear_sequence(self.out)
        self._run = _Run(_command(context, self.out), self.out)

    def _finish(self, context, cancelled=False):
        rc = self._run.proc.returncode
        written = self._run.frame if (cancelled or rc != 0) else self.frames
        if rc != 0 and not cancelled:
            self.report({"ERROR"}, "vdbclay: " + self._run.error())
            return {"CANCELLED"}
        if written >= 1:
            load_sequence(context, self.out, written)
        if cancelled:
            self.report({"WARNING"}, "vdbclay: cancelled after %d of %d frames (those are loaded)"
                        % (written, self.frames))
            return {"CANCELLED"}
        self.report({"INFO"}, "vdbclay: %d frames in %s" % (self.frames, self.out))
        return {"FINISHED"}

    def execute(self, context):
        # Waits for the run: scripts and `blender -b` (no event loop for a modal operator).
        try:
            self._start(context)
        except (RuntimeError, ValueError, OSError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, self.frames)
        try:
            while self._run.proc.poll() is None:
                p = self._run.poll()
                if p:
                    wm.progress_update(p[0])
                    print("vdbclay: frame %d/%d" % p, flush=True)
                try:
                    self._run.proc.wait(timeout=0.1)
                except subprocess.TimeoutExpired:
                    pass
            self._run.poll()
        except KeyboardInterrupt:
            self._run.proc.send_signal(signal.SIGINT)
            self._run.proc.wait()
            return self._finish(context, cancelled=True)
        finally:
            wm.progress_end()
        return self._finish(context)

    def invoke(self, context, event):
        try:
            self._start(context)
        except (RuntimeError, ValueError, OSError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, self.frames)
        self._timer = wm.event_timer_add(0.2, window=context.window)
        _settings(context).running = True
        _settings(context).progress = "starting"
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _end_modal(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        _settings(context).running = False
        _settings(context).progress = ""

    def modal(self, context, event):
        if event.type == "ESC":
            # SIGINT: vdbclay stops at the next step and writes a checkpoint; whole frames stay.
            self._run.proc.send_signal(signal.SIGINT)
            self._run.proc.wait()
            self._run.poll()
            self._end_modal(context)
            return self._finish(context, cancelled=True)
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        p = self._run.poll()
        if p:
            context.window_manager.progress_update(p[0])
            _settings(context).progress = "frame %d/%d" % p
            for area in context.screen.areas:
                if area.type == "VIEW_3D":
                    area.tag_redraw()
        if self._run.proc.poll() is None:
            return {"RUNNING_MODAL"}
        self._run.poll()
        self._end_modal(context)
        return self._finish(context)


class VDBCLAY_PT_panel(bpy.types.Panel):
    bl_label = "vdbclay"
    bl_idname = "VDBCLAY_PT_panel"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "vdbclay"

    def draw(self, context):
        layout = self.layout
        s = _settings(context)
        obj = context.active_object
        box = layout.box()
        if obj is not None and obj.type == "MESH":
            box.label(text=obj.name, icon="OBJECT_DATA")
            box.prop(obj.vdbclay, "role")
            if obj.vdbclay.role == "CLAY":
                box.prop(obj.vdbclay, "mass")
        else:
            box.label(text="Select a mesh object")
        row = layout.row(align=True)
        for role, label in (("CLAY", "Clay"), ("TOOL", "Tool"), ("OBSTACLE", "Obstacle"), ("NONE", "None")):
            row.operator("vdbclay.mark", text=label).role = role
        counts = ", ".join("%d %s" % (len(_marked(context, r)), r.lower())
                           for r in ("CLAY", "TOOL", "OBSTACLE"))
        layout.label(text=counts)
        col = layout.column()
        col.prop(s, "voxel_size")
        col.prop(s, "threshold")
        col.prop(s, "rule")
        col.prop(s, "push")
        col.prop(s, "transport")
        col.prop(s, "threads")
        col.prop(s, "output")
        col.prop(s, "executable")
        layout.label(text="Frames %d..%d" % (context.scene.frame_start, context.scene.frame_end))
        if s.running:
            layout.label(text="Running: %s (Esc cancels)" % s.progress, icon="TIME")
        else:
            layout.operator("vdbclay.run", icon="PLAY")
        row = layout.row(align=True)
        row.operator("vdbclay.export_scene")
        row.operator("vdbclay.load_sequence")


CLASSES = (VdbclayObjectSettings, VdbclaySceneSettings, VDBCLAY_OT_mark, VDBCLAY_OT_export_scene,
           VDBCLAY_OT_load_sequence, VDBCLAY_OT_run, VDBCLAY_PT_panel)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Object.vdbclay = bpy.props.PointerProperty(type=VdbclayObjectSettings)
    bpy.types.Scene.vdbclay = bpy.props.PointerProperty(type=VdbclaySceneSettings)


def unregister():
    del bpy.types.Scene.vdbclay
    del bpy.types.Object.vdbclay
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
