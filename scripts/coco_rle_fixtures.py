#!/usr/bin/env python3
"""Records pycocotools' mask API outputs as a fixture for tubeloc-core's RLE tests.

Run once (output committed): python3 scripts/coco_rle_fixtures.py core/tests/fixtures/rle_pycocotools.json
Inputs are generated deterministically (numpy RandomState(7)); every output is pycocotools'.
"""
import json
import sys

import numpy as np
from pycocotools import mask as mu


def rows(m):
    return ["".join(str(int(v)) for v in r) for r in m]


def rand_mask(rng, h, w, kind):
    if kind == "blob":
        yy, xx = np.mgrid[0:h, 0:w]
        m = np.zeros((h, w), np.uint8)
        for _ in range(rng.randint(1, 4)):
            cy, cx = rng.uniform(0, h), rng.uniform(0, w)
            ry, rx = rng.uniform(1, h / 2 + 1), rng.uniform(1, w / 2 + 1)
            m |= (((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 <= 1).astype(np.uint8)
        return m
    if kind == "noise":
        return (rng.uniform(size=(h, w)) < 0.3).astype(np.uint8)
    if kind == "empty":
        return np.zeros((h, w), np.uint8)
    if kind == "full":
        return np.ones((h, w), np.uint8)
    if kind == "pixel":
        m = np.zeros((h, w), np.uint8)
        m[rng.randint(h), rng.randint(w)] = 1
        return m
    raise ValueError(kind)


def enc(m):
    return mu.encode(np.asfortranarray(m.astype(np.uint8)))


def main(out):
    rng = np.random.RandomState(7)
    masks = []
    shapes = [(17, 23), (1, 9), (9, 1), (30, 40), (5, 5)]
    for h, w in shapes:
        for kind in ["blob", "blob", "noise", "empty", "full", "pixel"]:
            m = rand_mask(rng, h, w, kind)
            r = enc(m)
            masks.append({
                "h": h, "w": w, "rows": rows(m),
                "counts": r["counts"].decode(),
                "area": int(mu.area(r)),
                "bbox": [float(v) for v in mu.toBbox(r)],
            })
    # A large, sparse mask: long counts need several 5-bit chunks and negative deltas.
    big = np.zeros((600, 800), np.uint8)
    big[10:12, 5:700] = 1
    big[500:590, 790:800] = 1
    big[300, 400] = 1
    r = enc(big)
    big_case = {"h": 600, "w": 800, "ones": [[int(y), int(x)] for y, x in zip(*np.nonzero(big))],
                "counts": r["counts"].decode(), "area": int(mu.area(r)),
                "bbox": [float(v) for v in mu.toBbox(r)]}

    merges = []
    for i in range(0, len(masks) - 2, 3):
        group = [masks[i], masks[i + 1], masks[i + 2]]
        if len({(g["h"], g["w"]) for g in group}) != 1:
            continue
        rles = [{"size": [g["h"], g["w"]], "counts": g["counts"].encode()} for g in group]
        merges.append({"inputs": [i, i + 1, i + 2],
                       "union": mu.merge(rles, intersect=False)["counts"].decode(),
                       "intersection": mu.merge(rles, intersect=True)["counts"].decode()})

    ious = []
    for (h, w) in [(30, 40), (17, 23)]:
        dts = [rand_mask(rng, h, w, "blob") for _ in range(5)]
        gts = [rand_mask(rng, h, w, "blob") for _ in range(4)] + [np.zeros((h, w), np.uint8)]
        crowd = [0, 1, 0, 1, 0]
        d = [enc(m) for m in dts]
        g = [enc(m) for m in gts]
        o = mu.iou(d, g, crowd)
        ious.append({"h": h, "w": w, "dt": [x["counts"].decode() for x in d],
                     "gt": [x["counts"].decode() for x in g], "iscrowd": crowd,
                     "iou": [[float(v) for v in row] for row in o]})

    polys = []
    for _ in range(25):
        h, w = int(rng.randint(5, 40)), int(rng.randint(5, 40))
        n = int(rng.randint(3, 9))
        ps = []
        for _ in range(int(rng.randint(1, 3))):
            pts = rng.uniform(-3, max(h, w) + 3, size=2 * n)
            if rng.uniform() < 0.5:
                pts = np.round(pts * 2) / 2  # half-pixel vertices hit the rounding edge cases
            ps.append([float(v) for v in pts])
        each = [x["counts"].decode() for x in mu.frPyObjects(ps, h, w)]
        merged = mu.merge(mu.frPyObjects(ps, h, w))["counts"].decode()
        polys.append({"h": h, "w": w, "polygons": ps, "each": each, "merged": merged})
    # A regular shape and a tube-like rotated rectangle.
    tube = [[100.2, 40.5, 180.7, 95.1, 170.3, 110.9, 89.8, 56.2]]
    polys.append({"h": 160, "w": 220, "polygons": tube,
                  "each": [mu.frPyObjects(tube, 160, 220)[0]["counts"].decode()],
                  "merged": mu.merge(mu.frPyObjects(tube, 160, 220))["counts"].decode()})

    boxes = []
    for _ in range(15):
        h, w = int(rng.randint(5, 40)), int(rng.randint(5, 40))
        bb = [float(v) for v in np.round(rng.uniform(-3, 30, size=4) * 4) / 4]
        bb[2], bb[3] = abs(bb[2]), abs(bb[3])
        boxes.append({"h": h, "w": w, "bbox": bb,
                      "counts": mu.frPyObjects(np.array([bb]), h, w)[0]["counts"].decode()})

    d = np.round(rng.uniform(0, 50, size=(6, 4)), 2)
    g = np.round(rng.uniform(0, 50, size=(5, 4)), 2)
    g[0] = d[0]
    crowd = [1, 0, 0, 1, 0]
    bb_iou = {"dt": d.tolist(), "gt": g.tolist(), "iscrowd": crowd,
              "iou": mu.iou(d, g, crowd).tolist()}

    with open(out, "w") as f:
        json.dump({"generator": "scripts/coco_rle_fixtures.py, pycocotools " + __import__("importlib.metadata").metadata.version("pycocotools"),
                   "masks": masks, "big": big_case, "merges": merges, "ious": ious,
                   "polygons": polys, "boxes": boxes, "bbox_iou": bb_iou}, f, indent=0)


if __name__ == "__main__":
    main(sys.argv[1])
