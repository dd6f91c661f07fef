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


def test_pds_camera_list_gives_cameras_by_image_and_their_grounds(tmp_path):
    # A level camera 2 m above the ground, looking along the rover's +x, 30 degrees down
    # (rover frame: x forward, y right, z down; camera: x right, y down, z forward).
    s, c = 0.5, 0.8660254037844386
    r = [[0.0, 1.0, 0.0], [-s, 0.0, c], [c, 0.0, s]]
    entry = {"image": "images/NLB_1.jpg", "model_type": "CAHVOR", "image_width": 640, "image_height": 480,
             "fx": 500.0, "fy": 500.0, "cx": 319.5, "cy": 239.5, "skew": 0.1,
             "R_cam_from_ref": r, "camera_center_ref_m": [0.8, 0.4, -2.0],
             "R_cam_from_site": r, "camera_height_m": 2.0}
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps([entry, dict(entry, image="images/NLB_2.jpg", camera_height_m=1.5)]))
    rig = tubeloc.read_rig(path)
    assert rig.camera_names == ["NLB_1.jpg", "NLB_2.jpg"] and rig.image_size("NLB_2.jpg") == (640, 480)
    grounds = tubeloc.read_pds_grounds(path)
    nx, ny, nz, d = grounds["NLB_1.jpg"]
    # Up in the camera frame is -z of the site frame: (0, -c, -s); the camera is 2 m above.
    assert abs(nx) < 1e-12 and abs(ny + c) < 1e-12 and abs(nz + s) < 1e-12 and abs(d + 2.0) < 1e-12
    assert abs(grounds["NLB_2.jpg"][3] + 1.5) < 1e-12
    loc = tubeloc.Locator(rig, camera="NLB_2.jpg")
    assert loc.camera == "NLB_2.jpg"
    # One locator for every frame of the list: the camera switches, the model stays loaded.
    loc.select_camera("NLB_1.jpg")
    assert loc.camera == "NLB_1.jpg"
    with pytest.raises(tubeloc.TubelocError, match="no camera named \"NLB_9.jpg\""):
        loc.select_camera("NLB_9.jpg")
    assert loc.camera == "NLB_1.jpg"
    path.write_text(json.dumps([dict(entry, skew=5.0)]))
    with pytest.raises(tubeloc.TubelocError, match="entry 0: skew"):
        tubeloc.read_pds_grounds(path)


PDS3_LABEL = """PDS_VERSION_ID = PDS3
PRODUCT_ID = "NLB_7"
PLANET_DAY_NUMBER = 1431
GROUP = GEOMETRIC_CAMERA_MODEL_PARMS
  MODEL_TYPE = CAHV
  MODEL_COMPONENT_1 = (0.8, 0.3, -1.95)
  MODEL_COMPONENT_2 = (1.0, 0.0, 0.0)
  MODEL_COMPONENT_3 = (319.5, 500.0, 0.0)
  MODEL_COMPONENT_4 = (239.5, 0.0, 500.0)
END_GROUP = GEOMETRIC_CAMERA_MODEL_PARMS
OBJECT = IMAGE
  LINES = 480
  LINE_SAMPLES = 640
END_OBJECT = IMAGE
END
"""


def test_pds3_label_gives_its_camera_and_ground(tmp_path):
    # A camera 1.95 m above the rover frame's origin looking along the rover's +x (level).
    path = tmp_path / "NLB_7.LBL"
    path.write_text(PDS3_LABEL)
    rig = tubeloc.read_rig(path)
    assert rig.camera_names == ["NLB_7"] and rig.image_size("NLB_7") == (640, 480)
    nx, ny, nz, d = tubeloc.read_pds_grounds(path)["NLB_7"]
    # Up in the camera frame (x right, y down) is -y; the camera is 1.95 m above its ground.
    assert abs(nx) < 1e-12 and abs(ny + 1.0) < 1e-12 and abs(nz) < 1e-12 and abs(d + 1.95) < 1e-12
    path.write_text(PDS3_LABEL.replace("MODEL_TYPE = CAHV", "MODEL_TYPE = CAHVORE"))
    with pytest.raises(tubeloc.TubelocError, match="NLB_7.LBL.*CAHVORE"):
        tubeloc.read_rig(path)
