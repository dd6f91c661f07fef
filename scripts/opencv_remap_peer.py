#!/usr/bin/env python3
"""OpenCV peer for tubeloc's fisheye resampling (`LinearResampling::apply`): cv2.remap with
bilinear interpolation on the same image and the same map.

Usage: opencv_remap_peer.py IMAGE.npy MAPX.npy MAPY.npy OUT.npy RUNS
Times RUNS remaps, writes the last output to OUT.npy and prints one JSON object:
{"seconds": [wall time of each remap], "threads": cv2.getNumThreads()}.
Exit code 3 when cv2 is not installed (callers skip).
"""
import json
import sys
import time

try:
    import cv2
    import numpy as np
except ImportError:
    print("cv2/numpy not installed", file=sys.stderr)
    sys.exit(3)

image, mapx, mapy = (np.load(p) for p in sys.argv[1:4])
runs = int(sys.argv[5])
seconds = []
for _ in range(runs):
    t0 = time.perf_counter()
    out = cv2.remap(image, mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    seconds.append(time.perf_counter() - t0)
np.save(sys.argv[4], out)
print(json.dumps({"seconds": seconds, "threads": cv2.getNumThreads()}))
