"""Opens the sidebar on the vdbclay panel and saves a screenshot of the 3D view (run with a window,
under Xvfb: scripts/blender-screenshot.sh). Blender 3.4 gives scripts no way to pick the sidebar's
tab, so the panel is drawn in the Item tab, first."""
import sys, bpy, addon_utils
out_png = sys.argv[sys.argv.index("--") + 1]
addon_utils.enable("vdbclay_addon", default_set=True)
import vdbclay_addon
cls = vdbclay_addon.VDBCLAY_PT_panel
bpy.utils.unregister_class(cls)
cls.bl_category = "Item"
cls.bl_order = -100
bpy.utils.register_class(cls)

def setup():
    for area in bpy.context.window_manager.windows[0].screen.areas:
        if area.type == "VIEW_3D":
            area.spaces.active.show_region_ui = True
            area.spaces.active.overlay.show_floor = True
    return None

def shoot():
    win = bpy.context.window_manager.windows[0]
    area = next(a for a in win.screen.areas if a.type == "VIEW_3D")
    with bpy.context.temp_override(window=win, area=area):
        bpy.ops.screen.screenshot_area(filepath=out_png)
    print("shot", out_png)
    bpy.ops.wm.quit_blender()

bpy.app.timers.register(setup, first_interval=0.5)
bpy.app.timers.register(shoot, first_interval=3.0)
