#!/usr/bin/env python3
"""OpenCV StereoSGBM on a `tubeloc synth stereo` set, scored like `tubeloc stereo --set`.

Valid pixels: finite exact disparity d, x - d >= 0, not occluded (ordering constraint: hidden
when some x' > x in the row has x' - d(x') < x - d(x) + 0.5). Bad-t: no estimate or |error| > t.
MAE over pixels with an estimate. Tube pixels: valid pixels inside the visible tube masks.

Usage: scripts/stereo_synth_peer.py SET_DIR --min-disparity 16 --disparities 160 [--block 5]
       [--mode SGBM|HH|3WAY] [--ours OUT_DIR/stereo_eval.json]
Needs: numpy, opencv-contrib-python-headless, pycocotools.
"""
import argparse
import json
import os
import sys

import numpy as np

try:
    import cv2
    from pycocotools import mask as mask_utils
except ImportError as e:  # pragma: no cover
    sys.exit(f"needs opencv-contrib-python-headless and pycocotools: {e}")

sys.path.insert(0, os.path.dirname(__file__))
from stereo_peer import read_pfm  # noqa: E402


def valid_mask(gt):
    h, w = gt.shape
    m = np.zeros((h, w), bool)
    xs = np.arange(w, dtype=np.float64)
    for y in range(h):
        row = gt[y].astype(np.float64)
        ok = np.isfinite(row) & (row > 0)
        xr = np.where(ok, xs - row, np.inf)
        # min over x' > x of xr(x')
        suffix = np.minimum.accumulate(xr[::-1])[::-1]
        right_min = np.concatenate([suffix[1:], [np.inf]])
        m[y] = ok & (xr >= 0) & (xr <= right_min - 0.5)
    return m


class Acc:
    def __init__(self):
        self.n = self.est = self.b1 = self.b2 = 0
        self.abs = 0.0

    def add(self, est, gt, sel):
        e, g = est[sel], gt[sel]
        have = np.isfinite(e)
        err = np.abs(e[have] - g[have])
        self.n += e.size
        self.est += int(have.sum())
        self.b1 += int((~have).sum() + (err > 1).sum())
        self.b2 += int((~have).sum() + (err > 2).sum())
        self.abs += float(err.sum())

    def score(self):
        n = max(self.n, 1)
        return {"pixels": self.n, "density": self.est / n, "bad1": self.b1 / n, "bad2": self.b2 / n,
                "mae": self.abs / max(self.est, 1)}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("set")
    ap.add_argument("--min-disparity", type=int, default=0)
    ap.add_argument("--disparities", type=int, default=128)
    ap.add_argument("--block", type=int, default=5)
    ap.add_argument("--mode", default="SGBM", choices=["SGBM", "HH", "3WAY"])
    ap.add_argument("--ours")
    a = ap.parse_args()
    mode = {"SGBM": cv2.STEREO_SGBM_MODE_SGBM, "HH": cv2.STEREO_SGBM_MODE_HH, "3WAY": cv2.STEREO_SGBM_MODE_SGBM_3WAY}[a.mode]
    b = a.block
    m = cv2.StereoSGBM_create(minDisparity=a.min_disparity, numDisparities=a.disparities, blockSize=b, P1=8 * b * b,
                              P2=32 * b * b, disp12MaxDiff=1, uniquenessRatio=10, speckleWindowSize=100,
                              speckleRange=2, mode=mode)
    ds = json.load(open(os.path.join(a.set, "annotations.json")))
    valid, tube = Acc(), Acc()
    for im in ds["images"]:
        left = cv2.imread(os.path.join(a.set, "images", im["file_name"]), cv2.IMREAD_GRAYSCALE)
        right = cv2.imread(os.path.join(a.set, "right", im["right_file_name"]), cv2.IMREAD_GRAYSCALE)
        gt = read_pfm(os.path.join(a.set, "disparity", im["disparity_file_name"]))
        d16 = m.compute(left, right)
        est = d16.astype(np.float32) / 16.0
        est[d16 < (a.min_disparity * 16)] = np.nan
        vm = valid_mask(gt)
        valid.add(est, gt, vm)
        for ann in ds["annotations"]:
            if ann["image_id"] != im["id"]:
                continue
            tm = mask_utils.decode(ann["segmentation"]).astype(bool)
            tube.add(est, gt, vm & tm)
    res = {"method": f"OpenCV StereoSGBM {a.mode} block={b}", "pairs": len(ds["images"]),
           "valid": valid.score(), "tube": tube.score()}
    if a.ours:
        t = json.load(open(a.ours))["total"]
        res["tubeloc"] = {"valid": t["valid"], "tube": t["tube"]}
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
