#!/usr/bin/env python3
"""OpenCV peer for `tubeloc calib rig`: calibrateCamera per camera and stereoCalibrate per
stereo pair on the same corners of a calibration set written by `tubeloc synth calib`.

Usage: opencv_calib_peer.py SET_DIR [noisy|exact]
Prints one JSON object: {"cameras": {name: {fx, fy, cx, cy, dist[5], rms}},
"baselines": {"L-R": metres}, "seconds": wall time of the OpenCV calls}.
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


def main():
    d = sys.argv[1]
    src = sys.argv[2] if len(sys.argv) > 2 else "noisy"
    s = json.load(open(f"{d}/calib_set.json"))
    board = s["board"]
    half = board["tag_size_m"] / 2
    centres = {t["id"]: t["centre"] for t in board["tags"]}
    offs = [(-half, half), (half, half), (half, -half), (-half, -half)]
    per_cam = {}  # name -> {view: (obj Nx3, img Nx2, keys)}
    for v in s["views"]:
        for o in v["observations"]:
            obj, img, keys = [], [], []
            for t in o[src]:
                c = centres.get(t["id"])
                if c is None:
                    continue
                for k, (dx, dy) in enumerate(offs):
                    obj.append((c[0] + dx, c[1] + dy, 0.0))
                    img.append(t["corners"][k])
                    keys.append((t["id"], k))
            per_cam.setdefault(o["camera"], {})[v["index"]] = (
                np.array(obj, np.float32), np.array(img, np.float32), keys)
    cams = {c["name"]: c["model"] for c in s["rig"]["cameras"]}
    out = {"cameras": {}, "baselines": {}}
    t0 = time.perf_counter()
    calib = {}
    for name, views in per_cam.items():
        m = cams[name]
        size = (m["width"], m["height"])
        objs = [views[k][0] for k in sorted(views)]
        imgs = [views[k][1] for k in sorted(views)]
        rms, K, dist, _, _ = cv2.calibrateCamera(objs, imgs, size, None, None)
        calib[name] = (K, dist)
        out["cameras"][name] = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2],
                                "dist": dist.ravel()[:5].tolist(), "rms": rms}
    for left, right in s["rig"]["stereo_pairs"]:
        if left not in per_cam or right not in per_cam:
            continue
        objs, il, ir = [], [], []
        for k in sorted(set(per_cam[left]) & set(per_cam[right])):
            a, b = per_cam[left][k], per_cam[right][k]
            common = [key for key in a[2] if key in set(b[2])]
            if len(common) < 8:
                continue
            ia = {key: i for i, key in enumerate(a[2])}
            ib = {key: i for i, key in enumerate(b[2])}
            objs.append(np.array([a[0][ia[c]] for c in common], np.float32))
            il.append(np.array([a[1][ia[c]] for c in common], np.float32))
            ir.append(np.array([b[1][ib[c]] for c in common], np.float32))
        if not objs:
            continue
        (Kl, dl), (Kr, dr) = calib[left], calib[right]
        m = cams[left]
        res = cv2.stereoCalibrate(objs, il, ir, Kl, dl, Kr, dr, (m["width"], m["height"]),
                                  flags=cv2.CALIB_FIX_INTRINSIC)
        T = res[6]
        out["baselines"][f"{left}-{right}"] = float(np.linalg.norm(T))
    out["seconds"] = time.perf_counter() - t0
    print(json.dumps(out))


if __name__ == "__main__":
    main()
