"""coco_eval gives pycocotools' COCOeval.stats on a small seeded set (masks and boxes)."""

import contextlib
import io
import json

import numpy as np
import pytest

import tubeloc

pycocotools = pytest.importorskip("pycocotools", reason="pycocotools is installed by .ci/run")
from pycocotools import mask as mask_utils  # noqa: E402
from pycocotools.coco import COCO  # noqa: E402
from pycocotools.cocoeval import COCOeval  # noqa: E402


def rle(m):
    r = mask_utils.encode(np.asfortranarray(m.astype(np.uint8)))
    return {"size": [int(v) for v in r["size"]], "counts": r["counts"].decode("ascii")}


def bbox(m):
    ys, xs = np.nonzero(m)
    return [float(xs.min()), float(ys.min()), float(xs.max() - xs.min() + 1), float(ys.max() - ys.min() + 1)]


def small_set(tmp_path, seed=3):
    """Tubes as thin rotated bars of several sizes; detections jittered, some missed, some
    false, scores random."""
    rng = np.random.default_rng(seed)
    h, w = 96, 128
    yy, xx = np.mgrid[0:h, 0:w]

    def bar(cx, cy, length, width, angle):
        d = np.array([np.cos(angle), np.sin(angle)])
        u = (xx - cx) * d[0] + (yy - cy) * d[1]
        v = -(xx - cx) * d[1] + (yy - cy) * d[0]
        return (np.abs(u) <= length / 2) & (np.abs(v) <= width / 2)

    images, anns, results = [], [], []
    for image_id in range(1, 6):
        images.append({"id": image_id, "width": w, "height": h, "file_name": f"{image_id}.png"})
        for _ in range(rng.integers(1, 4)):
            cx, cy = rng.uniform(25, w - 25), rng.uniform(20, h - 20)
            length, width, angle = rng.uniform(8, 60), rng.uniform(3, 10), rng.uniform(0, np.pi)
            m = bar(cx, cy, length, width, angle)
            if m.sum() == 0:
                continue
            anns.append({"id": len(anns) + 1, "image_id": image_id, "category_id": 1, "segmentation": rle(m), "area": float(m.sum()), "bbox": bbox(m), "iscrowd": 0})
            if rng.random() < 0.8:
                d = bar(cx + rng.normal(0, 1.5), cy + rng.normal(0, 1.5), length * rng.uniform(0.8, 1.1), width, angle + rng.normal(0, 0.05))
                if d.sum():
                    results.append({"image_id": image_id, "category_id": 1, "score": float(rng.uniform(0.3, 1.0)), "segmentation": rle(d), "bbox": bbox(d)})
        if rng.random() < 0.6:
            d = bar(rng.uniform(20, w - 20), rng.uniform(20, h - 20), 20, 5, rng.uniform(0, np.pi))
            results.append({"image_id": image_id, "category_id": 1, "score": float(rng.uniform(0.0, 0.6)), "segmentation": rle(d), "bbox": bbox(d)})
    gt = {"images": images, "annotations": anns, "categories": [{"id": 1, "name": "tube"}]}
    gt_path, dt_path = tmp_path / "gt.json", tmp_path / "dt.json"
    gt_path.write_text(json.dumps(gt))
    dt_path.write_text(json.dumps(results))
    return gt_path, dt_path


def pycocotools_stats(gt_path, dt_path, iou_type):
    with contextlib.redirect_stdout(io.StringIO()):
        gt = COCO(str(gt_path))
        dt = gt.loadRes(str(dt_path))
        e = COCOeval(gt, dt, iou_type)
        e.evaluate()
        e.accumulate()
        e.summarize()
    return np.array(e.stats)


@pytest.mark.parametrize("iou_type", ["segm", "bbox"])
def test_coco_eval_equals_pycocotools(tmp_path, iou_type):
    gt_path, dt_path = small_set(tmp_path)
    ours = tubeloc.coco_eval(str(gt_path), str(dt_path), iou_type=iou_type)
    expected = pycocotools_stats(gt_path, dt_path, iou_type)
    assert ours["stats"].shape == (12,)
    assert ours["iou_type"] == iou_type
    assert 0.0 < expected[1] < 1.0, "the set is neither trivial nor empty"
    np.testing.assert_allclose(ours["stats"], expected, rtol=0, atol=1e-12)
    assert len(ours["summary"].splitlines()) == 12


def test_coco_eval_errors_name_the_file(tmp_path):
    gt_path, _ = small_set(tmp_path)
    bad = tmp_path / "bad.json"
    bad.write_text('[{"image_id": 99, "category_id": 1, "score": 0.5, "bbox": [0, 0, 4, 4]}]')
    with pytest.raises(tubeloc.TubelocError, match=f"loading results {bad}: .*image_id 99 is not in the ground truth"):
        tubeloc.coco_eval(str(gt_path), str(bad))
    with pytest.raises(tubeloc.TubelocError, match="unknown IoU type"):
        tubeloc.coco_eval(str(gt_path), str(bad), iou_type="keypoints")
