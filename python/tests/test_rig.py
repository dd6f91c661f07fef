"""read_rig / write_rig round trips."""

import json

import pytest

import tubeloc


def test_rig_file_round_trip(demo_scene, tmp_path):
    rig_path, _, _ = demo_scene
    rig = tubeloc.read_rig(rig_path)
    out = tmp_path / "sub" / "rig.json"
    out.parent.mkdir()
    tubeloc.write_rig(rig, out)
    back = tubeloc.read_rig(out)
    assert back == rig
    assert json.loads(out.read_text()) == json.loads(rig.to_json())
    original = json.loads(rig_path.read_text())
    written = json.loads(out.read_text())
    assert written["cameras"][0]["model"] == original["cameras"][0]["model"]
    assert back.camera_names == ["demo"] and back.stereo_pairs == []


def test_stereo_rig_from_json(tmp_path, demo_scene):
    rig_path, _, _ = demo_scene
    doc = json.loads(rig_path.read_text())
    left = doc["cameras"][0]
    right = dict(left, name="right", T_rig_cam={"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation": [0.2, 0, 0]})
    doc = {"cameras": [dict(left, name="left"), right], "stereo_pairs": [["left", "right"]]}
    rig = tubeloc.Rig.from_json(json.dumps(doc))
    assert rig.stereo_pairs == [("left", "right")]
    tubeloc.write_rig(rig, tmp_path / "stereo.json")
    assert tubeloc.read_rig(tmp_path / "stereo.json") == rig
    assert tubeloc.Locator(rig, detector="learned").camera == "left"


def test_invalid_rig_is_refused():
    with pytest.raises(tubeloc.TubelocError, match="no cameras"):
        tubeloc.Rig.from_json('{"cameras": [], "stereo_pairs": []}')


def test_opencv_yaml_round_trip(demo_scene, tmp_path):
    rig_path, _, _ = demo_scene
    rig = tubeloc.read_rig(rig_path)
    tubeloc.write_rig(rig, tmp_path / "rig.yaml")
    assert (tmp_path / "rig.yaml").read_text().startswith("%YAML:1.0")
    back = tubeloc.read_rig(tmp_path / "rig.yaml")
    assert back.camera_names == rig.camera_names
    a, b = json.loads(back.to_json()), json.loads(rig.to_json())
    assert a["cameras"][0]["model"]["width"] == b["cameras"][0]["model"]["width"]
    for k in ("fx", "fy", "cx", "cy"):
        assert a["cameras"][0]["model"][k] == pytest.approx(b["cameras"][0]["model"][k], rel=1e-12)
