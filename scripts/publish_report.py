#!/usr/bin/env python3
"""Copy the reports of a `tubeloc bench` (or `tubeloc eval`) output folder into docs/.

Usage: scripts/publish_report.py SRC DST

Copies `report.md`, `breakdown.md`, `bench_state.json`, `*.png` and the metric files
(`metrics.json`, `pose_metrics.json`, `breakdown.json`) under SRC to the same relative paths
under DST, leaving out the large or regenerable files (images, the full-resolution run's
images, detections, poses, SVG twins of the plots, per-pair `pose_eval.json`). Links in the copied Markdown files to files that were
not copied are removed (an SVG link line) or turned into plain text, so every link resolves.
"""
import os
import re
import shutil
import sys

KEEP_NAMES = {"report.md", "breakdown.md", "bench_state.json", "metrics.json", "pose_metrics.json", "breakdown.json"}
SKIP_DIRS = {"images", "right", "disparity", "set", "splits", "fullres"}


def wanted(name):
    return name in KEEP_NAMES or name.endswith(".png")


def fix_links(path):
    text = open(path, encoding="utf-8").read()
    out = []
    for line in text.split("\n"):
        links = re.findall(r"\]\(([^)#]+)\)", line)
        missing = [l for l in links if not l.startswith("http") and not os.path.exists(os.path.join(os.path.dirname(path), l))]
        if missing:
            if re.fullmatch(r"\[[^\]]*\(SVG\)\]\([^)]*\.svg\)\s*", line):
                continue
            for l in missing:
                line = re.sub(r"\[([^\]]*)\]\(" + re.escape(l) + r"\)", r"\1", line)
            if "pose_eval.json" in missing[0]:
                line = line.rstrip(".") + " (written by the command; not committed)."
        out.append(line)
    text = re.sub(r"\n\n\n+", "\n\n", "\n".join(out))
    open(path, "w", encoding="utf-8").write(text)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    src, dst = sys.argv[1], sys.argv[2]
    if not os.path.isdir(src):
        sys.exit(f"{src}: not a folder")
    copied = []
    for root, dirs, files in os.walk(src):
        dirs[:] = sorted(d for d in dirs if d not in SKIP_DIRS)
        for name in sorted(files):
            if wanted(name):
                rel = os.path.relpath(os.path.join(root, name), src)
                os.makedirs(os.path.dirname(os.path.join(dst, rel)) or ".", exist_ok=True)
                shutil.copyfile(os.path.join(root, name), os.path.join(dst, rel))
                copied.append(rel)
    for rel in copied:
        if rel.endswith(".md"):
            fix_links(os.path.join(dst, rel))
    print(f"{len(copied)} files copied to {dst}")


if __name__ == "__main__":
    main()
