"""The demo scene, made with the CLI: what `tubeloc demo` renders (tiny preset, one with-tags
scene, half scale, 512 px crops, seed 7), with a one-camera rig of its first image's camera
and that image's nominal ground plane, as the demo's `locate` step uses them."""

import json
import subprocess
from pathlib import Path

import numpy as np


def nominal_ground(image_entry) -> str:
    """The image's nominal ground "nx,ny,nz,d" in the camera frame: the world plane
    z = ground_height_m seen from T_world_cam (X_w = R X_c + t, so n = R^T e_z, d = h - t_z)."""
    t = image_entry["T_world_cam"]
    r = np.array(t["rotation"], dtype=float)
    tz = float(t["translation"][2])
    h = float(image_entry.get("ground_height_m", 0.0))
    return ",".join(repr(float(v)) for v in (*r[2, :], h - tz))


def make_demo_scene(exe: Path, out: Path):
    """Renders the scene under `out` with the `tubeloc` binary `exe`; returns (rig path,
    image path, ground "nx,ny,nz,d")."""
    dataset = out / "dataset"
    args = [str(exe), "synth", "--preset", "tiny", "--scenes", "1", "--scale", "0.5", "--resolution", "512", "--seed", "7", "--force", "--out", str(dataset)]
    p = subprocess.run(args, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(args)} failed:\n{p.stderr}")
    first = json.loads((dataset / "annotations.json").read_text())["images"][0]
    identity = {"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0, 0, 0]}
    rig = {"cameras": [{"name": "demo", "model": first["camera"], "T_rig_cam": identity}], "stereo_pairs": []}
    (out / "rig.json").write_text(json.dumps(rig))
    return out / "rig.json", dataset / "images" / first["file_name"], nominal_ground(first)
