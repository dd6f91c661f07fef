#!/usr/bin/env python3
"""OpenCV contrib LINE-2D (cv2.linemod) on the same templates and frames as tubeloc's Line2D bench.

Input directory (written by `cargo bench -p tubeloc-detect --bench line2d`):
  image.png      the 1024x1024 RGB test image (when no --image is given)
  masks.bin      the library's level-0 silhouettes: u32 count, then per template u16 width,
                 u16 height and width*height mask bytes (0/1), little endian.
Each silhouette is given to addTemplate as a white-on-black image with its mask (OpenCV extracts
its own contour features from it, as ours does from the same silhouette), with T = {4, 8}
(OpenCV's LINE-2D crashes unless W and W/2 are multiples of 16). Prints one JSON line with, per
frame, the median match time and CPU time, all threads (gradients, response maps and matching
together, as cv2 does them in one call), in-process.

Usage: python3 scripts/linemod_peer.py DIR [--image NAME=PATH ...] [--repeats 5] [--threshold 80] [--features 63]
"""
import argparse
import json
import os
import statistics
import struct
import sys
import time

import numpy as np

try:
    import cv2
except ImportError:
    print(json.dumps({"error": "cv2 missing: pip install opencv-contrib-python-headless"}))
    sys.exit(2)


def load_masks(path):
    with open(path, "rb") as f:
        data = f.read()
    (n,) = struct.unpack_from("<I", data, 0)
    off = 4
    masks = []
    for _ in range(n):
        w, h = struct.unpack_from("<HH", data, off)
        off += 4
        m = np.frombuffer(data, dtype=np.uint8, count=w * h, offset=off).reshape(h, w)
        off += w * h
        masks.append(m)
    return masks


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threshold", type=float, default=80.0)
    ap.add_argument("--features", type=int, default=63)
    ap.add_argument("--image", action="append", default=[], help="NAME=PATH of a frame to match (repeatable)")
    a = ap.parse_args()
    frames = []
    for item in a.image or ["image=" + os.path.join(a.dir, "image.png")]:
        name, sep, path = item.partition("=")
        if not sep:
            print(json.dumps({"error": f"--image {item!r}: expected NAME=PATH"}))
            sys.exit(2)
        frames.append((name, path))
    if not hasattr(cv2, "linemod"):
        print(json.dumps({"error": "cv2.linemod missing: install opencv-contrib-python-headless"}))
        sys.exit(2)
    masks = load_masks(os.path.join(a.dir, "masks.bin"))
    det = cv2.linemod.Detector([cv2.linemod.ColorGradient_create(10.0, a.features, 55.0)], [4, 8])
    t0 = time.perf_counter()
    added = 0
    pad = 8
    for m in masks:
        mm = np.pad(m * 255, pad).astype(np.uint8)
        src = cv2.cvtColor(mm, cv2.COLOR_GRAY2BGR)
        tid, _ = det.addTemplate([src], "tube", mm)
        added += tid >= 0
    t_add = time.perf_counter() - t0
    out = {}
    for name, path in frames:
        img = cv2.imread(path, cv2.IMREAD_COLOR)
        if img is None:
            print(json.dumps({"error": f"{path}: cannot read the image"}))
            sys.exit(2)
        h, w = img.shape[:2]
        if w % 16 or (w // 2) % 16:
            print(json.dumps({"error": f"{path}: OpenCV LINE-2D needs W and W/2 multiples of 16, got W = {w}"}))
            sys.exit(2)
        times = []
        cpu = []
        matches = []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            c0 = time.process_time()
            matches, _ = det.match([img], a.threshold, ["tube"])
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        best = matches[0] if matches else None
        out[name] = {
            "image": [w, h],
            "match_ms_median": round(1000 * statistics.median(times), 2),
            "match_ms_all": [round(1000 * t, 2) for t in times],
            "match_cpu_ms_median": round(1000 * statistics.median(cpu), 2),
            "matches": len(matches),
            "best": None if best is None else {"x": best.x, "y": best.y, "similarity": best.similarity, "template_id": best.template_id},
        }
    print(json.dumps({
        "peer": "opencv-contrib cv2.linemod LINE-2D",
        "opencv": cv2.__version__,
        "threads": cv2.getNumThreads(),
        "templates": added,
        "T": [4, 8],
        "add_templates_s": round(t_add, 3),
        "frames": out,
    }))


if __name__ == "__main__":
    main()
