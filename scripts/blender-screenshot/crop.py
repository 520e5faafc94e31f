"""Crops the screenshot to the clay and the sidebar (run in `blender -b`: its image API, no PIL)."""
import sys, bpy, numpy as np
src, dst = sys.argv[sys.argv.index("--") + 1:]
im = bpy.data.images.load(src)
w, h = im.size
px = np.array(im.pixels[:], dtype=np.float32).reshape(h, w, 4)  # rows bottom to top
x0, x1 = 330, w                      # the clay, the tool and the sidebar
top_cut, bottom_cut = 0, 250         # rows from the top / bottom to drop
crop = px[bottom_cut:h - top_cut, x0:x1, :].copy()
ch, cw = crop.shape[:2]
out = bpy.data.images.new("crop", cw, ch, alpha=False)
out.pixels[:] = crop.ravel()
out.filepath_raw = dst
out.file_format = "PNG"
bpy.context.scene.render.image_settings.compression = 100
out.save()
print("cropped", cw, ch)
