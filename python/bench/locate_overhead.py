"""Per-call overhead of `tubeloc.Locator.locate` from Python against the Rust call it wraps.

The Rust figure is `Locator::locate`'s own wall time (`Locator.last_timings["total_s"]`,
measured inside the pipeline); the Python figure is the wall time of the Python call around
it, which adds the numpy -> image copy, releasing and taking the GIL, and building the result
objects. Both come from the same calls, so the difference is the binding's cost alone.

    python python/bench/locate_overhead.py [--repeats 21] [--tubeloc target/release/tubeloc]

The scene is the demo's (`tubeloc synth --preset tiny --scenes 1 --scale 0.5 --resolution
512 --seed 7`, the first image with its camera and nominal ground), made with the CLI.
"""

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import tubeloc

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python" / "tests"))
from demo_scene import make_demo_scene  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--tubeloc", type=Path, default=Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target")) / "release" / "tubeloc")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rig, image, ground = make_demo_scene(a.tubeloc, Path(tmp))
        locator = tubeloc.Locator(str(rig))
        img = tubeloc.read_image(image)
        for _ in range(2):
            locator.locate(img, ground=ground)
        wall, inner = [], []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            tubes = locator.locate(img, ground=ground)
            wall.append(time.perf_counter() - t0)
            inner.append(locator.last_timings["total_s"])
        over = [w - i for w, i in zip(wall, inner)]
    med = statistics.median
    print(f"image {img.shape[1]}x{img.shape[0]} {img.dtype}, {len(tubes)} tube(s), {a.repeats} calls")
    print(f"Rust Locator::locate   median {med(inner) * 1e3:9.3f} ms")
    print(f"Python Locator.locate  median {med(wall) * 1e3:9.3f} ms")
    print(f"overhead per call      median {med(over) * 1e3:9.3f} ms ({med(over) / med(inner) * 100:.2f} % of the Rust call)")


if __name__ == "__main__":
    main()
