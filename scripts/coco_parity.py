#!/usr/bin/env python3
"""Runs pycocotools' COCOeval on a ground-truth and a results file and writes what tubeloc's
parity tests compare: the 12 stats, eval['precision'] and eval['recall'] flattened in C order
(T x R x K x A x M and T x K x A x M), and the text summarize() prints.

usage: coco_parity.py GT.json DT.json segm|bbox OUT.json
"""
import contextlib
import io
import json
import sys

from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval


def main(gt_path, dt_path, iou_type, out_path):
    noise = io.StringIO()
    with contextlib.redirect_stdout(noise):
        gt = COCO(gt_path)
        dt = gt.loadRes(dt_path)
        ev = COCOeval(gt, dt, iou_type)
        ev.evaluate()
        ev.accumulate()
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        ev.summarize()
    out = {
        "stats": [float(v) for v in ev.stats],
        "precision_shape": list(ev.eval["precision"].shape),
        "precision": [float(v) for v in ev.eval["precision"].ravel()],
        "recall": [float(v) for v in ev.eval["recall"].ravel()],
        "summary": text.getvalue(),
    }
    with open(out_path, "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    main(*sys.argv[1:5])
