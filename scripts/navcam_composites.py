#!/usr/bin/env python3
"""Composites of rendered tubes on the full-resolution Navcam frames of the training sols (the
sol 1431 stereo pair, the only 1024x1024 grey frames outside the validation and test sols), seen
through a Navcam-like camera: f = 1225 px (45 degree field of view), 1.6-2.0 m above level
ground, looking 25-45 degrees down, sun at a random azimuth and 20-75 degrees elevation, 1-4
tubes and dust 0-0.5 each. One `tubeloc synth composite` call per composite, then one COCO set.
Deterministic: composite k draws its view from Python's `random.Random(k * 7919)` and passes
`--seed k`.

usage: navcam_composites.py TUBELOC REAL_DATA OUT [PER_FRAME=50] [PITCH_MIN=25] [PITCH_MAX=45] [FIRST=1]

PITCH_MIN / PITCH_MAX: the range of the downward look, degrees (12 and 28 put the tubes at about
4 m median, the range of the grey validation composites). FIRST: the index of the first
composite (its seeds); sets meant to be trained on together need disjoint indices.
"""
import json
import math
import os
import random
import subprocess
import sys
import tempfile

FRAMES = ["NLB_524534514EDR_F0562034NCAM00280M_.jpg", "NRB_524534514EDR_F0562034NCAM00280M_.jpg"]
CAMERA = {"width": 1024, "height": 1024, "fx": 1225.0, "fy": 1225.0, "cx": 511.5, "cy": 511.5,
          "distortion": {"k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "k3": 0.0}}


def main(tubeloc, data, out, per_frame=50, pitch_min=25, pitch_max=45, first=1):
    if os.path.exists(out):
        sys.exit(f"{out}: exists; choose a new folder")
    work = tempfile.mkdtemp(prefix="navcam-")
    camera = os.path.join(work, "camera.json")
    with open(camera, "w") as f:
        json.dump(CAMERA, f)
    os.makedirs(os.path.join(out, "images"))
    merged = {"images": [], "annotations": [], "categories": None,
              "info": {"description": "tubeloc composites on the full-resolution Navcam frames of the training sols",
                       "script": "scripts/navcam_composites.py", "per_frame": per_frame,
                      "pitch_deg": [pitch_min, pitch_max], "first": first}}
    k = first - 1
    for frame in FRAMES:
        background = os.path.join(data, "backgrounds", "msl_navcam_1024", frame)
        for _ in range(per_frame):
            k += 1
            r = random.Random(k * 7919)
            pitch, height = math.radians(r.uniform(pitch_min, pitch_max)), r.uniform(1.6, 2.0)
            azimuth, elevation, tubes, dust = r.uniform(-180, 180), r.uniform(20, 75), r.randint(1, 4), r.uniform(0, 0.5)
            # n . X = d with n up in the camera frame (camera pitched down) and d = -height.
            ground = "%f,%f,%f,%f" % (0, -math.cos(pitch), -math.sin(pitch), -height)
            one = os.path.join(work, f"c{k}")
            subprocess.run([tubeloc, "synth", "composite", "--background", background, "--camera", camera,
                            f"--ground={ground}", f"--sun={azimuth},{elevation}", "--tubes", str(tubes),
                            "--dust", str(dust), "--seed", str(k), "--out", one], check=True, stdout=subprocess.DEVNULL)
            with open(os.path.join(one, "annotations.json")) as f:
                d = json.load(f)
            merged["categories"] = d["categories"]
            for image in d["images"]:
                old, new = image["id"], len(merged["images"]) + 1
                name = f"{new:04d}_{image['file_name']}"
                os.replace(os.path.join(one, "images", image["file_name"]), os.path.join(out, "images", name))
                image.update(id=new, file_name=name, grey=True, background=frame)
                merged["images"].append(image)
                for a in d["annotations"]:
                    if a["image_id"] == old:
                        a.update(id=len(merged["annotations"]) + 1, image_id=new)
                        merged["annotations"].append(a)
    with open(os.path.join(out, "annotations.json"), "w") as f:
        json.dump(merged, f)
    print(f"{len(merged['images'])} composites, {len(merged['annotations'])} tubes -> {out}")


if __name__ == "__main__":
    if not 4 <= len(sys.argv) <= 8:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2], sys.argv[3], *(int(a) for a in sys.argv[4:]))
