#!/usr/bin/env python3
"""Darkened copies of a COCO image set, as a shorter exposure would give them.

Each stored level x (8-bit, grey or colour) becomes

    y = clip(round(g x + n), 0, 255),   n ~ N(0, sigma^2) per pixel (and channel),

with g the exposure gain and sigma the read noise in levels that the shorter exposure adds
(the real MSL rear Hazcam frame of sol 3423 shows about 2.5 levels). The annotations are
copied unchanged. Seeded: the same seed gives the same images.

usage: exposure_sweep.py SRC_DIR OUT_DIR GAIN [SIGMA] [SEED]
"""
import json
import os
import shutil
import sys

import numpy as np
from PIL import Image


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    src, out, gain = sys.argv[1], sys.argv[2], float(sys.argv[3])
    sigma = float(sys.argv[4]) if len(sys.argv) > 4 else 2.5
    seed = int(sys.argv[5]) if len(sys.argv) > 5 else 0
    if not 0.0 < gain <= 1.0:
        sys.exit(f"gain {gain}: expected 0 < GAIN <= 1")
    ann = os.path.join(src, "annotations.json")
    ds = json.load(open(ann))
    os.makedirs(os.path.join(out, "images"), exist_ok=True)
    rng = np.random.default_rng(seed)
    for im in ds["images"]:
        img = Image.open(os.path.join(src, "images", im["file_name"]))
        mode = "L" if img.mode in ("L", "I;16", "I") else "RGB"
        x = np.asarray(img.convert(mode), dtype=np.float64)
        y = np.clip(np.round(gain * x + rng.normal(0.0, sigma, x.shape)), 0, 255).astype(np.uint8)
        name = os.path.splitext(im["file_name"])[0] + ".png"
        Image.fromarray(y, mode).save(os.path.join(out, "images", name))
        im["file_name"] = name
    json.dump(ds, open(os.path.join(out, "annotations.json"), "w"))


if __name__ == "__main__":
    main()
