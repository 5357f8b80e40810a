"""docs/images/datasets.png: COCO masks, visible and amodal boxes and motion vectors drawn
over a render (docs/DATASETS.md).

    python -m benchmarks.make_dataset_figure
"""

import json
import os
import tempfile

import numpy as np
from PIL import Image, ImageDraw

from rtmesh.cli import main as rtmesh_main
from rtmesh.io.images import read_image
from rtmesh.io.passes import id_colours

SCENE = """
[render]
width = 320
height = 240
spp = 16
[camera]
position = [0.0, 1.6, 6.0]
look_at = [0.0, 0.5, 0.0]
fov = 40
shutter = [0.0, 1.0]
[materials.floor]
diffuse = [0.6, 0.6, 0.55]
[materials.red]
diffuse = [0.7, 0.15, 0.1]
[materials.blue]
diffuse = [0.15, 0.3, 0.7]
[materials.green]
diffuse = [0.2, 0.6, 0.25]
[[lights]]
type = "point"
position = [3.0, 5.0, 4.0]
intensity = 40.0
[[objects]]
name = "floor"
category = "floor"
primitive = "plane"
size = [12.0, 12.0]
rotate = [-90.0, 0.0, 0.0]
material = "floor"
[[objects]]
name = "crate"
category = "box"
primitive = "box"
extents = [1.2, 1.2, 1.2]
translate = [-0.9, 0.6, -0.5]
rotate = [0.0, 25.0, 0.0]
material = "red"
[[objects]]
name = "ball"
category = "ball"
primitive = "icosphere"
radius = 0.55
translate = [0.1, 0.55, 0.6]
material = "blue"
motion = { translate = [0.15, 0.0, 0.0] }
[[objects]]
name = "tower"
category = "box"
primitive = "box"
extents = [0.6, 1.8, 0.6]
translate = [1.4, 0.9, -1.2]
material = "green"
motion = { rotate_axis = [0.0, 1.0, 0.0], rotate_degrees = 20.0 }
"""


def main():
    out_png = os.path.join(os.path.dirname(__file__), "..", "docs", "images", "datasets.png")
    with tempfile.TemporaryDirectory() as folder:
        scene = os.path.join(folder, "scene.toml")
        with open(scene, "w", encoding="utf-8") as f:
            f.write(SCENE)
        exr, coco = os.path.join(folder, "scene.exr"), os.path.join(folder, "scene.coco.json")
        assert rtmesh_main(["render", scene, "-o", exr, "--passes", "object_id,motion", "--annotations", coco,
                            "-q"]) == 0
        pixels, names = read_image(exr)
        with open(coco, encoding="utf-8") as f:
            document = json.load(f)
    image = np.clip(pixels[..., :3] / (1.0 + pixels[..., :3]), 0, 1) ** (1 / 2.2)
    ids = pixels[..., names.index("object_id.id")]
    tint = id_colours(ids)
    shown = np.where(ids[..., None] > 0, 0.55 * image + 0.45 * tint, image)  # the floor untinted
    canvas = Image.fromarray(np.round(255 * shown).astype(np.uint8)).resize((640, 480), Image.NEAREST)
    draw = ImageDraw.Draw(canvas)
    scale = 2
    for ann in document["annotations"]:
        if ann["object_name"] == "floor":
            continue
        x, y, w, h = (v * scale for v in ann["bbox"])
        draw.rectangle([x, y, x + w, y + h], outline=(255, 255, 255), width=2)
        xa, ya, wa, ha = (v * scale for v in ann["bbox_amodal"])
        for i in range(int(xa), int(xa + wa), 10):  # dashed amodal box
            draw.line([i, ya, min(i + 5, xa + wa), ya], fill=(255, 230, 0), width=2)
            draw.line([i, ya + ha, min(i + 5, xa + wa), ya + ha], fill=(255, 230, 0), width=2)
        for j in range(int(ya), int(ya + ha), 10):
            draw.line([xa, j, xa, min(j + 5, ya + ha)], fill=(255, 230, 0), width=2)
            draw.line([xa + wa, j, xa + wa, min(j + 5, ya + ha)], fill=(255, 230, 0), width=2)
        draw.text((x + 3, y + 3), f"{ann['object_name']} {ann['visible_fraction']:.2f}", fill=(255, 255, 255))
    motion = pixels[..., names.index("motion.X"):names.index("motion.Y") + 1]
    for row in range(3, motion.shape[0], 10):
        for column in range(3, motion.shape[1], 10):
            dx, dy = motion[row, column]
            if abs(dx) + abs(dy) > 0.5:
                x0, y0 = (column + 0.5) * scale, (row + 0.5) * scale
                draw.line([x0, y0, x0 + dx * scale, y0 + dy * scale], fill=(0, 255, 255), width=1)
                draw.ellipse([x0 - 1, y0 - 1, x0 + 1, y0 + 1], fill=(0, 255, 255))
    canvas.save(out_png)
    print(out_png)


if __name__ == "__main__":
    main()
