"""`tubeloc.Locator.locate` returns the poses `tubeloc locate` writes for the same inputs."""

import json
import platform
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import tubeloc

TOL = 1e-9


def cli_locate(cli, tmp_path, rig, image, *extra):
    out = tmp_path / "poses.json"
    cli("locate", "--rig", rig, "--image", image, "--out", out, *extra)
    return json.loads(out.read_text())


def write_grey_png(path, grey):
    """Writes an 8-bit grey HxW array as a PNG (zlib, no filter)."""
    import struct  # noqa: PLC0415
    import zlib  # noqa: PLC0415

    h, w = grey.shape
    raw = b"".join(b"\x00" + grey[y].astype(np.uint8).tobytes() for y in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    Path(path).write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def assert_same_tube(py_tube, cli_tube):
    assert py_tube.status == cli_tube["status"]
    assert py_tube.converged == cli_tube["converged"]
    assert py_tube.score == pytest.approx(cli_tube["score"], abs=TOL)
    assert py_tube.probability == pytest.approx(cli_tube["probability"], abs=TOL)
    if "pose_evidence" in cli_tube:
        assert py_tube.pose_evidence == pytest.approx(cli_tube["pose_evidence"], abs=TOL)
    else:
        assert py_tube.pose_evidence is None
    assert py_tube.end_confidence == pytest.approx(cli_tube["end_confidence"], abs=TOL)
    for field in ("centre", "axis", "end_direction"):
        np.testing.assert_allclose(getattr(py_tube, field), cli_tube[field], rtol=0, atol=TOL, err_msg=field)
    np.testing.assert_allclose(py_tube.covariance, cli_tube["covariance"], rtol=0, atol=TOL)
    for field, key in (("t_cam_grasp", "T_cam_grasp"), ("t_rig_grasp", "T_rig_grasp")):
        m = getattr(py_tube, field)
        assert m.shape == (4, 4)
        np.testing.assert_allclose(m[:3, :3], cli_tube[key]["rotation"], rtol=0, atol=TOL, err_msg=field)
        np.testing.assert_allclose(m[:3, 3], cli_tube[key]["translation"], rtol=0, atol=TOL, err_msg=field)
        np.testing.assert_array_equal(m[3], [0, 0, 0, 1])
    failure = cli_tube.get("failure")
    assert py_tube.failure == (failure["reason"] if failure else None)
    # Every other field of the file (residuals, seed_kept, end_anchored...) as the CLI wrote it.
    assert py_tube.to_dict() == cli_tube


@pytest.mark.parametrize("with_ground", [True, False], ids=["ground", "no-ground"])
def test_locate_equals_the_cli_on_the_demo_scene(cli, demo_scene, tmp_path, with_ground):
    rig, image, ground = demo_scene
    extra = ["--ground", ground] if with_ground else []
    doc = cli_locate(cli, tmp_path, rig, image, *extra)
    locator = tubeloc.Locator(str(rig))
    tubes = locator.locate(tubeloc.read_image(image), ground=ground if with_ground else None)
    assert len(doc["tubes"]) > 0, "the demo scene has tubes"
    assert [t.status for t in tubes] == [t["status"] for t in doc["tubes"]]
    for py_tube, cli_tube in zip(tubes, doc["tubes"]):
        assert_same_tube(py_tube, cli_tube)
    assert locator.min_probability == pytest.approx(doc["min_probability"], abs=0)
    assert locator.camera == doc["camera"]
    assert locator.detector == doc["detector"]


def test_ground_as_numbers_equals_ground_as_text(demo_scene):
    rig, image, ground = demo_scene
    locator = tubeloc.Locator(tubeloc.read_rig(rig))
    img = tubeloc.read_image(image)
    a = [t.to_dict() for t in locator.locate(img, ground=ground)]
    b = [t.to_dict() for t in locator.locate(img, ground=[float(v) for v in ground.split(",")])]
    assert a == b


def test_detect_then_refine_equals_the_cli(cli, demo_scene, tmp_path):
    rig, image, ground = demo_scene
    rig_doc = json.loads(rig.read_text())
    camera = tmp_path / "camera.json"
    camera.write_text(json.dumps(rig_doc["cameras"][0]["model"]))
    dets_path, poses_path = tmp_path / "dets.json", tmp_path / "poses.json"
    cli("detect", "--method", "learned", "--image", image, "--camera", camera, "--ground", ground, "--out", dets_path)
    cli("refine", "--image", image, "--camera", camera, "--detections", dets_path, "--ground", ground, "--out", poses_path)
    img = tubeloc.read_image(image)
    dets = tubeloc.detect(img, str(rig), ground=ground)
    assert dets == json.loads(dets_path.read_text())
    poses = tubeloc.refine(img, dets, str(rig), ground=ground)
    cli_poses = json.loads(poses_path.read_text())
    assert [p.to_dict() for p in poses] == cli_poses
    for p, c in zip(poses, cli_poses):
        np.testing.assert_allclose(p.centre, c["centre"], rtol=0, atol=TOL)
        assert p.status is None and p.t_cam_grasp is None and p.probability is None
    # The pose evidence of each tube is the score `--pose-evidence` gives its snapped detection.
    snapped_path = tmp_path / "snapped.json"
    cli("refine", "--image", image, "--camera", camera, "--detections", dets_path, "--ground", ground, "--out", poses_path, "--snapped-out", snapped_path, "--pose-evidence", "shipped")
    snapped = json.loads(snapped_path.read_text())
    assert len(snapped) == len(poses)
    for p, s in zip(poses, snapped):
        assert tubeloc.pose_evidence(p) == pytest.approx(s["score"], abs=1e-12)
        assert 0.0 <= tubeloc.pose_evidence(p, "shipped") <= 1.0
    with pytest.raises(tubeloc.TubelocError, match="absent.json"):
        tubeloc.pose_evidence(poses[0], "absent.json")


def test_an_underexposed_frame_hands_over_no_tube(demo_scene):
    # The demo scene at a sixth of its brightness: what was located is listed as
    # `underexposed`, as `tubeloc locate` does; min_highlight_level=0 turns the guard off.
    rig, image, ground = demo_scene
    bright = tubeloc.read_image(image)
    dark = bright // 6
    found = tubeloc.Locator(str(rig)).locate(bright, ground=ground)
    located = [t for t in found if t.status == "located"]
    assert located, "the demo scene locates tubes"
    dimmed = tubeloc.Locator(str(rig)).locate(dark, ground=ground)
    assert not [t for t in dimmed if t.status == "located"]
    assert [t for t in dimmed if t.status == "underexposed"]
    unguarded = tubeloc.Locator(str(rig), min_highlight_level=0).locate(dark, ground=ground)
    assert not [t for t in unguarded if t.status == "underexposed"]
    with pytest.raises(tubeloc.TubelocError, match="grey level in \\[0, 255\\]"):
        tubeloc.Locator(str(rig), min_highlight_level=300)


def test_the_pose_evidence_floor_is_the_clis(cli, demo_scene, tmp_path):
    # The learned model's pose evidence is checked at the CLI's default floor; a floor of 1
    # turns every tube the score accepts into `weak_pose_evidence`, as --min-pose-evidence 1.
    rig, image, _ = demo_scene
    found = tubeloc.Locator(str(rig)).locate(tubeloc.read_image(str(image)))
    located = [t for t in found if t.status == "located"]
    assert located and all(t.pose_evidence is not None and t.pose_evidence >= 0.3 for t in located)
    strict = tubeloc.Locator(str(rig), min_pose_evidence=1.0).locate(tubeloc.read_image(str(image)))
    assert not [t for t in strict if t.status == "located"]
    passed = [t for t in found if t.status in ("located", "intersects_tube", "weak_pose_evidence", "limbs_continue")]
    assert len([t for t in strict if t.status == "weak_pose_evidence"]) == len(passed)
    out = tmp_path / "strict.json"
    p = cli("locate", "--rig", rig, "--image", image, "--min-pose-evidence", "1", "--out", out, check=False)
    assert p.returncode == 3, p.stderr  # no tube located
    doc = json.loads(out.read_text())
    assert doc["min_pose_evidence"] == 1.0
    assert [t["status"] for t in doc["tubes"]] == [t.status for t in strict]
    with pytest.raises(tubeloc.TubelocError, match="min_pose_evidence"):
        tubeloc.Locator(str(rig), min_pose_evidence=1.5)


def test_the_limb_continuation_cut_is_the_clis(cli, demo_scene, tmp_path):
    # Every converged tube whose ends lie in the frame carries its limb continuation; located
    # tubes lie at or under the CLI's default cut. A tiny cut turns every such tube into
    # `limbs_continue`, as --max-limb-continuation does (one whose end lies out of the frame
    # is not measured, and stays located); 0 turns the check off.
    rig, image, _ = demo_scene
    img = tubeloc.read_image(str(image))
    found = tubeloc.Locator(str(rig)).locate(img)
    located = [t for t in found if t.status == "located"]
    measured = [t for t in located if t.limb_continuation is not None]
    assert measured and all(t.limb_continuation <= 0.6 for t in measured)
    strict = tubeloc.Locator(str(rig), max_limb_continuation=1e-6).locate(img)
    going_on = [t for t in strict if t.status == "limbs_continue"]
    assert len(going_on) == len(measured) and all(t.limb_continuation > 1e-6 for t in going_on)
    assert all(t.limb_continuation is None for t in strict if t.status == "located")
    out = tmp_path / "strict.json"
    p = cli("locate", "--rig", rig, "--image", image, "--max-limb-continuation", "1e-6", "--out", out, check=False)
    assert p.returncode in (0, 3), p.stderr
    doc = json.loads(out.read_text())
    assert doc["max_limb_continuation"] == 1e-6
    assert [t["status"] for t in doc["tubes"]] == [t.status for t in strict]
    off = tubeloc.Locator(str(rig), max_limb_continuation=0).locate(img)
    assert not [t for t in off if t.status == "limbs_continue"]
    assert len([t for t in off if t.status == "located"]) >= len(located)
    with pytest.raises(tubeloc.TubelocError, match="max_limb_continuation"):
        tubeloc.Locator(str(rig), max_limb_continuation=-1.0)


def test_ignore_mask_equals_the_cli(cli, demo_scene, tmp_path):
    # A mask over the whole frame: every tube located without it is listed as
    # `in_ignored_region`, as `tubeloc locate --ignore-mask` lists it; an empty mask changes
    # nothing; a mask of another size raises the CLI's message.
    rig, image, ground = demo_scene
    img = tubeloc.read_image(image)
    locator = tubeloc.Locator(str(rig))
    plain = locator.locate(img, ground=ground)
    located = [t for t in plain if t.status == "located"]
    assert located, "the demo scene locates tubes"
    full = np.full(img.shape[:2], 255, dtype=np.uint8)
    mask_path = tmp_path / "mask.png"
    write_grey_png(mask_path, full)
    out = tmp_path / "poses.json"
    run = cli("locate", "--rig", rig, "--image", image, "--out", out, "--ground", ground, "--ignore-mask", mask_path, check=False)
    assert run.returncode == 3, run.stderr  # no tube located
    doc = json.loads(out.read_text())
    masked = locator.locate(img, ground=ground, ignore_mask=full)
    assert [t.status for t in masked] == [t["status"] for t in doc["tubes"]]
    assert sum(t.status == "in_ignored_region" for t in masked) == len(located)
    for py_tube, cli_tube in zip(masked, doc["tubes"]):
        assert_same_tube(py_tube, cli_tube)
    empty = locator.locate(img, ground=ground, ignore_mask=np.zeros(img.shape[:2], dtype=np.uint8))
    assert [t.to_dict() for t in empty] == [t.to_dict() for t in plain]
    with pytest.raises(tubeloc.TubelocError, match="ignore mask is 10x10"):
        locator.locate(img, ground=ground, ignore_mask=np.zeros((10, 10), dtype=np.uint8))


def test_fused_detect_equals_the_cli(cli, demo_scene, tmp_path):
    # The learned detections and Line2D's pose-verified ones by their pose evidence: the same
    # boxes and scores as `tubeloc detect --method fused`.
    rig, image, ground = demo_scene
    camera = tmp_path / "camera.json"
    camera.write_text(json.dumps(json.loads(rig.read_text())["cameras"][0]["model"]))
    lib, dets_path = tmp_path / "lib.tlt", tmp_path / "dets.json"
    cli("templates", "build", "--camera", camera, "--distances", "1.0:3.5:0.25", "--step-deg", "12", "--out", lib)
    cli("detect", "--method", "fused", "--templates", lib, "--image", image, "--camera", camera, "--ground", ground, "--out", dets_path)
    cli_dets = json.loads(dets_path.read_text())
    dets = tubeloc.detect(tubeloc.read_image(image), str(rig), detector="fused", templates=str(lib), ground=ground)
    assert dets, "the demo scene's tubes are found"
    assert [(d["bbox"], d["score"]) for d in dets] == [(c["bbox"], c["score"]) for c in cli_dets]
    for c in cli_dets:
        assert 0.0 <= c["score"] <= 1.0
        assert c["source"] in ("learned", "line2d"), c
        if c["source"] == "line2d":
            assert c["pose_probability"] == c["score"], c  # verified on the given ground
    # The Locator hands fused tubes over at the fused calibration's threshold, as `locate` does.
    cal = json.loads((Path(__file__).resolve().parents[2] / "data/models/fused.calibration.json").read_text())
    assert tubeloc.Locator(str(rig), detector="fused", templates=str(lib)).min_probability == cal["threshold"]


def test_line2d_without_templates_uses_the_default_library(cli, demo_scene, tmp_path):
    # Without a library, Python and the CLI both search with the default one.
    rig, image, ground = demo_scene
    camera = tmp_path / "camera.json"
    camera.write_text(json.dumps(json.loads(rig.read_text())["cameras"][0]["model"]))
    dets_path = tmp_path / "dets.json"
    cli("detect", "--method", "line2d", "--image", image, "--camera", camera, "--ground", ground, "--out", dets_path)
    cli_dets = json.loads(dets_path.read_text())
    dets = tubeloc.detect(tubeloc.read_image(image), str(rig), detector="line2d", ground=ground)
    assert dets, "the demo scene's tubes are found"
    assert [(d["bbox"], d["score"]) for d in dets] == [(c["bbox"], c["score"]) for c in cli_dets]


def test_keeping_freed_memory_changes_no_result(demo_scene):
    # The allocator policy the CLI sets at start: applied in this process, the poses are the
    # same to the bit (it changes only where freed memory goes).
    rig, image, ground = demo_scene
    locator = tubeloc.Locator(str(rig))
    img = tubeloc.read_image(image)
    before = [t.to_dict() for t in locator.locate(img, ground=ground)]
    applied = tubeloc.keep_freed_memory()
    assert applied == (sys.platform == "linux" and platform.libc_ver()[0] == "glibc")
    after = [t.to_dict() for t in locator.locate(img, ground=ground)]
    assert after == before and len(before) > 0


def test_a_frame_too_coarse_for_the_detector_is_warned_about():
    # A 256 px Navcam-like frame (binned on board) shows tubes about 1.4 px wide at their
    # expected range: the locator says so, as `tubeloc locate` does; a full frame is not warned.
    x, y = np.meshgrid(np.arange(256), np.arange(256))
    frame = (60 + (7 * x + 13 * y) % 90).astype(np.uint8)
    rig, ground = tubeloc.assumed_view("navcam", 256, 256)
    with pytest.warns(UserWarning, match=r"about 1\.\d px wide in this image, under the 4 px"):
        tubeloc.Locator(rig).locate(frame, ground=ground)
    rig, ground = tubeloc.assumed_view("navcam", 1024, 1024)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tubeloc.Locator(rig).locate(np.tile(frame, (4, 4)), ground=ground)
