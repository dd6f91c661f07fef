#!/usr/bin/env python3
"""OpenCV StereoSGBM peer for tubeloc-stereo: accuracy on Middlebury cones and timing.

accuracy: scores OpenCV StereoSGBM (several configurations, colour and grey input) and our
          disparity (a PFM written by tubeloc) with the SAME metric as
          tubeloc_stereo::metrics: evaluated pixels = GT known and non-occluded (left-right check
          of disp2/disp6: |dL - dR(round(x - dL))| <= 1); bad = invalid or |d - gt| > t; MAE over
          evaluated pixels with an estimate.
    python3 scripts/stereo_peer.py accuracy --data DIR --ours ours.pfm [--ndisp 64]
bench:    times StereoSGBM modes SGBM (default), 3WAY and HH on a pair, median of N runs.
    python3 scripts/stereo_peer.py bench --left L.png --right R.png --ndisp 128 [--repeat 7]
Prints one JSON object on stdout.
"""
import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

try:
    import cv2
except ImportError:  # the callers skip when OpenCV is missing
    print("stereo_peer: OpenCV (cv2) is not installed; pip install opencv-contrib-python-headless", file=sys.stderr)
    sys.exit(3)


def read_pfm(path):
    with open(path, "rb") as f:
        data = f.read()
    parts = data.split(maxsplit=4)
    kind, w, h, scale = parts[0], int(parts[1]), int(parts[2]), float(parts[3])
    assert kind == b"Pf", "expected a greyscale PFM"
    header_len = len(b" ".join(parts[:4])) + 1
    # Find the real header length (fields separated by single whitespace bytes).
    header_len = 0
    fields = 0
    while fields < 4:
        while data[header_len:header_len + 1].isspace():
            header_len += 1
        while not data[header_len:header_len + 1].isspace():
            header_len += 1
        fields += 1
    header_len += 1
    dtype = "<f4" if scale < 0 else ">f4"
    arr = np.frombuffer(data, dtype=dtype, count=w * h, offset=header_len).reshape(h, w)[::-1].astype(np.float32)
    arr = arr.copy()
    arr[~np.isfinite(arr)] = np.nan
    return arr


def ground_truth(data_dir, scale=4.0):
    gl = cv2.imread(f"{data_dir}/disp2.png", cv2.IMREAD_GRAYSCALE).astype(np.float32)
    gr = cv2.imread(f"{data_dir}/disp6.png", cv2.IMREAD_GRAYSCALE).astype(np.float32)
    dl = np.where(gl > 0, gl / scale, np.nan)
    dr = np.where(gr > 0, gr / scale, np.nan)
    h, w = dl.shape
    xs = np.arange(w)[None, :].repeat(h, 0).astype(np.float32)
    ys = np.arange(h)[:, None].repeat(w, 1)
    xr = np.floor(xs - dl + 0.5)  # same rounding as Rust f32::round for positive values
    inside = np.isfinite(dl) & (xr >= 0) & (xr < w)
    xr_i = np.where(inside, xr, 0).astype(np.int64)
    dr_at = dr[ys, xr_i]
    mask = inside & np.isfinite(dr_at) & (np.abs(dl - dr_at) <= 1.0)
    return dl, mask


def score(est, dl, mask, t):
    e = est[mask]
    g = dl[mask]
    valid = np.isfinite(e)
    err = np.abs(e[valid] - g[valid])
    n = int(mask.sum())
    bad = int((~valid).sum() + (err > t).sum())
    return {"evaluated": n, "bad": bad / max(n, 1), "mae": float(err.mean()) if err.size else 0.0,
            "density": float(valid.sum()) / max(n, 1)}


def sgbm(ndisp, block, cn, mode, uniq=10, speckle=100):
    return cv2.StereoSGBM_create(minDisparity=0, numDisparities=ndisp, blockSize=block,
                                 P1=8 * cn * block * block, P2=32 * cn * block * block,
                                 disp12MaxDiff=1, uniquenessRatio=uniq, speckleWindowSize=speckle,
                                 speckleRange=2, mode=mode)


def to_float(d16, min_disp=0):
    d = d16.astype(np.float32) / 16.0
    d[d16 < min_disp * 16] = np.nan  # invalid pixels are (minDisparity - 1) * 16
    return d


MODES = {"SGBM": cv2.STEREO_SGBM_MODE_SGBM, "3WAY": cv2.STEREO_SGBM_MODE_SGBM_3WAY, "HH": cv2.STEREO_SGBM_MODE_HH}


def accuracy(args):
    dl, mask = ground_truth(args.data)
    out = {"metric": "non-occluded (GT left-right check, 1 px), GT known; invalid counts as bad", "results": []}
    if args.ours:
        est = read_pfm(args.ours)
        out["results"].append({"method": "tubeloc SGM (census)", **{f"bad{t}": score(est, dl, mask, t)["bad"] for t in (1.0, 2.0)},
                               **score(est, dl, mask, 2.0)})
    colour = [cv2.imread(f"{args.data}/{n}.png", cv2.IMREAD_COLOR) for n in ("im2", "im6")]
    grey = [cv2.cvtColor(c, cv2.COLOR_BGR2GRAY) for c in colour]
    for mode_name in ("SGBM", "HH", "3WAY"):
        for block in (3, 5, 7):
            for cname, imgs, cn in (("colour", colour, 3), ("grey", grey, 1)):
                m = sgbm(args.ndisp, block, cn, MODES[mode_name])
                est = to_float(m.compute(imgs[0], imgs[1]))
                s = score(est, dl, mask, 2.0)
                out["results"].append({"method": f"OpenCV StereoSGBM {mode_name} block={block} {cname}",
                                       "bad1.0": score(est, dl, mask, 1.0)["bad"], "bad2.0": s["bad"], **s})
    ocv = [r for r in out["results"] if r["method"].startswith("OpenCV")]
    out["best_opencv"] = min(ocv, key=lambda r: r["bad2.0"])
    print(json.dumps(out, indent=1))


def bench(args):
    left = cv2.imread(args.left, cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(args.right, cv2.IMREAD_GRAYSCALE)
    cv2.setNumThreads(args.threads)
    res = {"size": [left.shape[1], left.shape[0]], "ndisp": args.ndisp, "opencv_threads": cv2.getNumThreads(),
           "median_ms": {}, "bad2.0": {}}
    gt = vis = None
    if args.gt:
        gt = read_pfm(args.gt)
        vis = cv2.imread(args.visible, cv2.IMREAD_GRAYSCALE) > 0
    for name in ("SGBM", "3WAY"):
        m = sgbm(args.ndisp, args.block, 1, MODES[name])
        d = m.compute(left, right)  # warm-up (allocations)
        ts = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            m.compute(left, right)
            ts.append((time.perf_counter() - t0) * 1e3)
        res["median_ms"]["opencv_" + name] = statistics.median(ts)
        if gt is not None:
            res["bad2.0"]["opencv_" + name] = score(to_float(d), gt, vis, 2.0)["bad"]
    if args.ours_criterion:
        import glob
        import os
        for est in glob.glob(os.path.join(args.ours_criterion, "*", "new", "estimates.json")):
            name = est.split(os.sep)[-3]
            with open(est) as f:
                res["median_ms"]["tubeloc_" + name] = json.load(f)["median"]["point_estimate"] / 1e6
    if args.ours and gt is not None:
        res["bad2.0"]["tubeloc_eight_paths"] = score(read_pfm(args.ours), gt, vis, 2.0)["bad"]
        four = args.ours.replace("ours_eight_paths", "ours_four_paths")
        if four != args.ours and os.path.exists(four):
            res["bad2.0"]["tubeloc_four_paths"] = score(read_pfm(four), gt, vis, 2.0)["bad"]
    ms = res["median_ms"]
    # Speed-up of ours over each OpenCV mode (> 1: ours is faster), per configuration of ours.
    res["ratio_opencv_over_ours"] = {
        o: {k: v / ms[o] for k, v in ms.items() if k.startswith("opencv")} for o in ms if o.startswith("tubeloc")
    }
    print(json.dumps(res, indent=1))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("accuracy")
    a.add_argument("--data", required=True)
    a.add_argument("--ours")
    a.add_argument("--ndisp", type=int, default=64)
    b = sub.add_parser("bench")
    b.add_argument("--left", required=True)
    b.add_argument("--right", required=True)
    b.add_argument("--ndisp", type=int, default=128)
    b.add_argument("--block", type=int, default=3)
    b.add_argument("--repeat", type=int, default=7)
    b.add_argument("--threads", type=int, default=2)
    b.add_argument("--gt", help="exact disparity PFM of the pair")
    b.add_argument("--visible", help="PNG mask of pixels to evaluate (non-zero)")
    b.add_argument("--ours", help="our disparity PFM on the same pair")
    b.add_argument("--ours-criterion", help="criterion group folder with our timings")
    args = ap.parse_args()
    accuracy(args) if args.cmd == "accuracy" else bench(args)


if __name__ == "__main__":
    main()
