#!/usr/bin/env python3
"""Interleaved timing of tubeloc SGM and OpenCV StereoSGBM on the 1024x768, 128-disparity bench
pair, for machines whose load fluctuates: R rounds, each timing OpenCV SGBM, OpenCV 3WAY, ours
(8 paths) and ours (4 paths) with N runs; prints the median and minimum of all runs per method
and the ratios OpenCV / ours (> 1: ours faster).

Usage: scripts/stereo_bench_interleaved.py [--rounds 5] [--runs 5] [--threads 2]
  (run `cargo bench -p tubeloc-stereo --bench sgm` or scripts/stereo_bench.sh once first so the
  pair exists in $CARGO_TARGET_DIR/stereo_bench, and build the example:
  `cargo build --release -p tubeloc-stereo --example sgm_time`)
"""
import argparse
import json
import os
import statistics
import subprocess
import time

import cv2


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    target = os.environ.get("CARGO_TARGET_DIR", os.path.join(os.path.dirname(__file__), "..", "target"))
    exe = os.path.join(target, "release", "examples", "sgm_time")
    left = cv2.imread(os.path.join(target, "stereo_bench", "left.png"), cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(os.path.join(target, "stereo_bench", "right.png"), cv2.IMREAD_GRAYSCALE)
    cv2.setNumThreads(a.threads)
    env = dict(os.environ, RAYON_NUM_THREADS=str(a.threads))
    b = 5
    matchers = {name: cv2.StereoSGBM_create(minDisparity=0, numDisparities=128, blockSize=b, P1=8 * b * b, P2=32 * b * b,
                                            disp12MaxDiff=1, uniquenessRatio=10, speckleWindowSize=100, speckleRange=2, mode=mode)
                for name, mode in (("opencv_SGBM", cv2.STEREO_SGBM_MODE_SGBM), ("opencv_3WAY", cv2.STEREO_SGBM_MODE_SGBM_3WAY))}
    times = {k: [] for k in ("opencv_SGBM", "opencv_3WAY", "tubeloc_eight_paths", "tubeloc_four_paths")}
    for _ in range(a.rounds):
        for name, m in matchers.items():
            m.compute(left, right)
            for _ in range(a.runs):
                t0 = time.perf_counter()
                m.compute(left, right)
                times[name].append((time.perf_counter() - t0) * 1e3)
        for paths in ("eight", "four"):
            out = subprocess.run([exe, paths, str(a.runs)], env=env, capture_output=True, text=True, check=True).stdout
            line = next(l for l in out.splitlines() if l.startswith("times_ms"))
            times[f"tubeloc_{paths}_paths"] += [float(v) for v in line.split()[1:]]
    res = {"threads": a.threads, "rounds": a.rounds, "runs_per_round": a.runs,
           "median_ms": {k: statistics.median(v) for k, v in times.items()},
           "min_ms": {k: min(v) for k, v in times.items()}}
    for stat in ("median_ms", "min_ms"):
        s = res[stat]
        res["ratio_opencv_over_ours_" + stat] = {o: {k: s[k] / s[o] for k in s if k.startswith("opencv")} for o in s if o.startswith("tubeloc")}
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
