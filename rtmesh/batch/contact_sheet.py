"""Contact sheets: one grid image of a batch's thumbnails per output folder, with names.

``rtmesh batch ... --contact-sheet`` writes ``rtmesh-contact-sheet.png`` in every output
folder that holds images of the batch (done by this run or finished before), for eyeballing
a collection: each image is scaled to fit a :data:`TILE` pixel square, laid out in rows of
``ceil(sqrt(n))``, in name order, with its name (image key without the folder) below it.
"""

import math
import os

from PIL import Image, ImageDraw

from rtmesh.io.atomic_files import replace_atomically

SHEET_NAME = "rtmesh-contact-sheet.png"
TILE = 128  # pixels, the largest side of a thumbnail
LABEL = 14  # pixels of text under each thumbnail
_FORMATS = (".png", ".jpg")


def write_contact_sheets(outdir, images):
    """Write one contact sheet per folder.

    Parameters
    ----------
    outdir : str
    images : iterable of (str, list of str)
        ``(key, files)`` of each finished image, names relative to ``outdir``; images with
        no PNG or JPEG file are left out.

    Returns
    -------
    list of str
        The sheets written.
    """
    folders = {}
    for key, files in images:
        pictures = [f for f in files if os.path.splitext(f)[1].lower() in _FORMATS
                    and not f.endswith((".depth.png", ".mask.png"))]
        if pictures:
            folders.setdefault(os.path.dirname(key), []).append((os.path.basename(key), pictures[0]))
    written = []
    for folder, tiles in sorted(folders.items()):
        path = os.path.join(outdir, folder, SHEET_NAME)
        sheet = contact_sheet([(name, os.path.join(outdir, file)) for name, file in sorted(tiles)])
        replace_atomically(path, lambda tmp: sheet.save(tmp, format="PNG"))
        written.append(path)
    return written


def contact_sheet(tiles):
    """The grid image of ``tiles`` (``(label, image path)`` pairs), RGB on white."""
    columns = max(1, math.ceil(math.sqrt(len(tiles))))
    rows = math.ceil(len(tiles) / columns)
    sheet = Image.new("RGB", (columns * TILE, rows * (TILE + LABEL)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for i, (label, file) in enumerate(tiles):
        x, y = (i % columns) * TILE, (i // columns) * (TILE + LABEL)
        with Image.open(file) as image:
            image = image.convert("RGB")
            image.thumbnail((TILE, TILE))
            sheet.paste(image, (x + (TILE - image.width) // 2, y + (TILE - image.height) // 2))
        text = label if len(label) <= 20 else label[:9] + "..." + label[-8:]
        draw.text((x + 2, y + TILE + 1), text, fill=(0, 0, 0))
    return sheet
