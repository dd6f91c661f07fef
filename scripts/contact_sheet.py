"""Tiles the preview renders (synth/examples/preview.rs) into a labelled contact sheet.

Usage: python3 scripts/contact_sheet.py PREVIEW_DIR docs/contact_sheet.png
Each tile is a 1024x1024 half-resolution crop, labelled "terrain time split height" from its
file name. Needs Pillow.
"""
import os
import sys

from PIL import Image, ImageDraw


def main(src, dst, tile=384, cols=5):
    names = sorted(n for n in os.listdir(src) if n.endswith(".png") and n[:2].isdigit())
    rows = (len(names) + cols - 1) // cols
    sheet = Image.new("RGB", (cols * tile, rows * tile), (0, 0, 0))
    for i, n in enumerate(names):
        im = Image.open(os.path.join(src, n)).convert("RGB").resize((tile, tile), Image.LANCZOS)
        d = ImageDraw.Draw(im)
        label = " ".join(os.path.splitext(n)[0].split("_")[1:]).replace(" h", " ") + " m"
        d.rectangle([0, 0, tile, 16], fill=(0, 0, 0))
        d.text((4, 2), label, fill=(255, 255, 255))
        sheet.paste(im, ((i % cols) * tile, (i // cols) * tile))
    os.makedirs(os.path.dirname(dst) or ".", exist_ok=True)
    sheet.save(dst)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
