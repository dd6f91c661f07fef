"""read_rig / write_rig round trips."""

import json

import numpy as np
import pytest

import tubeloc
from conftest import REPO


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


def test_one_camera_model_is_a_mono_rig(tmp_path):
    # What `--camera` takes is also a rig, as `tubeloc locate --rig camera.json` takes it.
    cam = {"width": 64, "height": 48, "fx": 60.0, "fy": 60.0, "cx": 31.5, "cy": 23.5}
    path = tmp_path / "cam.json"
    path.write_text(json.dumps(cam))
    rig = tubeloc.read_rig(path)
    assert '"camera"' in repr(rig)
    assert tubeloc.Locator(path, detector="learned").camera == "camera"
    assert tubeloc.detect(np.zeros((48, 64, 3), np.uint8), path) == []
    with pytest.raises(tubeloc.TubelocError, match="48x64 but rig camera"):
        tubeloc.detect(np.zeros((64, 48, 3), np.uint8), path)


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


def pds_entry(**changes):
    """An entry of a PDS camera list (`cahv_to_pinhole.py`'s shape): a level camera 2 m above
    the ground, looking along the rover's +x, 30 degrees down (rover frame: x forward, y right,
    z down; camera: x right, y down, z forward), with `changes` applied."""
    s, c = 0.5, 0.8660254037844386
    r = [[0.0, 1.0, 0.0], [-s, 0.0, c], [c, 0.0, s]]
    entry = {"image": "images/NLB_1.jpg", "model_type": "CAHVOR", "image_width": 640, "image_height": 480,
             "fx": 500.0, "fy": 500.0, "cx": 319.5, "cy": 239.5, "skew": 0.1,
             "R_cam_from_ref": r, "camera_center_ref_m": [0.8, 0.4, -2.0],
             "R_cam_from_site": r, "camera_height_m": 2.0}
    return dict(entry, **changes)


def test_pds_camera_list_gives_cameras_by_image_and_their_grounds(tmp_path):
    s, c = 0.5, 0.8660254037844386  # sine and cosine of the 30 degree look down
    entry = pds_entry()
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
    path.write_text(fisheye(PDS3_LABEL))
    with pytest.raises(tubeloc.TubelocError, match="NLB_7.LBL.*CAHVORE.*tubeloc locate"):
        tubeloc.read_rig(path)


def fisheye(label):
    """`label` with its CAHV model made a CAHVORE fisheye (type 2) with that linear part."""
    return label.replace("MODEL_TYPE = CAHV", "MODEL_TYPE = CAHVORE").replace(
        "END_GROUP = GEOMETRIC_CAMERA_MODEL_PARMS",
        "  MODEL_COMPONENT_5 = (1.0, 0.0, 0.0)\n  MODEL_COMPONENT_6 = (0.0, 0.0, 0.0)\n"
        "  MODEL_COMPONENT_7 = (0.0, 0.0, 0.0)\n  MODEL_COMPONENT_8 = 2\nEND_GROUP = GEOMETRIC_CAMERA_MODEL_PARMS")


def test_read_product_gives_image_rig_and_ground_a_fisheye_resampled(tmp_path):
    # A 64x48 8-bit product (label at the head, samples from record 5 of 256 bytes) whose
    # columns are numbered 0..63, as a CAHV camera and as a fisheye with that linear part.
    cahv = (PDS3_LABEL.replace("319.5, 500.0", "31.5, 40.0").replace("239.5, 0.0, 500.0", "23.5, 0.0, 40.0")
            .replace("LINES = 480", "LINES = 48").replace("LINE_SAMPLES = 640", "LINE_SAMPLES = 64")
            .replace("END_OBJECT", "  SAMPLE_TYPE = UNSIGNED_INTEGER\n  SAMPLE_BITS = 8\nEND_OBJECT")
            .replace("PDS_VERSION_ID = PDS3\n", "PDS_VERSION_ID = PDS3\nRECORD_TYPE = FIXED_LENGTH\nRECORD_BYTES = 256\n^IMAGE = 5\n"))
    columns = np.tile(np.arange(64, dtype=np.uint8) * 4, (48, 1))
    for name, label in [("PIN.IMG", cahv), ("FISH.IMG", fisheye(cahv))]:
        (tmp_path / name).write_bytes(label.encode().ljust(1024, b" ") + columns.tobytes())
    image, rig, ground = tubeloc.read_product(tmp_path / "PIN.IMG")
    assert np.array_equal(image, columns) and rig == tubeloc.read_rig(tmp_path / "PIN.IMG")
    assert ground == tubeloc.read_pds_grounds(tmp_path / "PIN.IMG")["NLB_7"]
    image, fish_rig, fish_ground = tubeloc.read_product(tmp_path / "FISH.IMG")
    # The same pinhole and ground; the image resampled: the centre stays, the edges are drawn
    # in from the fisheye's compressed rim (the pinhole's edge column lies nearer the centre
    # in the raw frame).
    assert fish_rig == rig and fish_ground == ground and image.shape == (48, 64)
    assert abs(int(image[24, 32]) - int(columns[24, 32])) <= 2
    assert image[24, 0] > columns[24, 0] + 8 and image[24, 63] < columns[24, 63] - 8
    with pytest.raises(tubeloc.TubelocError, match="x.png: not a PDS3 product"):
        (tmp_path / "x.png").write_bytes(b"\x89PNG")
        tubeloc.read_product(tmp_path / "x.png")


def test_assumed_view_locates_as_the_command_line_does(cli, tmp_path):
    # A real Navcam frame without a camera model (held out for false positives): the rig and
    # ground of the assumed Navcam view give the tubes of `tubeloc locate --assumed-view navcam`.
    frame = REPO.parent / "shared/data/real_mars/negatives_val/msl_navcam_1024/NLB_485117349EDR_F0480412NCAM00385M_.jpg"
    if not frame.exists():
        pytest.skip(f"{frame} is missing (../shared/data beside the repository)")
    rig, ground = tubeloc.assumed_view("navcam", 1024, 1024)
    assert rig.image_size("assumed") == (1024, 1024)
    assert ground[3] == pytest.approx(-1.9) and ground[:3] == pytest.approx((0.0, -np.cos(np.radians(30)), -np.sin(np.radians(30))))
    tubes = tubeloc.Locator(rig).locate(tubeloc.read_image(frame), ground=list(ground))
    out = tmp_path / "poses.json"
    cli("locate", "--assumed-view", "navcam", "--image", frame, "--out", out, check=False)
    doc = json.loads(out.read_text())
    assert len(tubes) == len(doc["tubes"]) > 0
    for t, d in zip(tubes, doc["tubes"]):
        assert t.status == d["status"] and t.probability == pytest.approx(d["probability"], abs=1e-9)
        assert np.allclose(t.centre, d["centre"], atol=1e-9)
    with pytest.raises(tubeloc.TubelocError, match="navcam, mast"):
        tubeloc.assumed_view("hazcam", 1024, 1024)
    # A view given by its numbers: field of view, height, downward look.
    rig, ground = tubeloc.assumed_view("90,2,25", 1024, 768)
    assert rig.image_size("assumed") == (1024, 768)
    assert ground == pytest.approx((0.0, -np.cos(np.radians(25)), -np.sin(np.radians(25)), -2.0))
    with pytest.raises(tubeloc.TubelocError, match="field of view 180"):
        tubeloc.assumed_view("180,2,25", 1024, 768)
    with pytest.raises(tubeloc.TubelocError):
        tubeloc.assumed_view("mast", 0, 0)


def test_product_names_give_their_cameras_views(tmp_path):
    # Curiosity Mastcam right (M-100), Perseverance Mastcam-Z at 110 mm, a Hazcam (no mast
    # view), a file without a product name.
    assert tubeloc.view_of_product("negatives_val/x/0079MR0005910210103981E01.jpg") == "m100"
    name = tubeloc.view_of_product("ZL0_0053_0671642352_402ECM_N0032046ZCAM05025_110085J01.png")
    assert name == "mastcam-z-110"
    assert tubeloc.view_of_product("RLB_701384675RAS_F0933408RHAZ00337M1.png") is None
    assert tubeloc.view_of_product("scene.png") is None
    # The name gives the camera: a 110 mm Mastcam-Z frame's focal length is 4x the 26 mm one's.
    rig, ground = tubeloc.assumed_view(name, 1648, 1200)
    wide, _ = tubeloc.assumed_view("mastcam-z-26", 1648, 1200)
    fx = []
    for r, path in ((rig, tmp_path / "z110.json"), (wide, tmp_path / "z26.json")):
        tubeloc.write_rig(r, path)
        fx.append(json.loads(path.read_text())["cameras"][0]["model"]["fx"])
    assert fx[0] == pytest.approx(fx[1] * 110 / 26, rel=1e-9)
    assert fx[1] == pytest.approx(824 / np.tan(np.radians(12.8)), rel=1e-9)
    assert ground[3] == pytest.approx(-2.0)
    with pytest.raises(tubeloc.TubelocError, match="26 to 110"):
        tubeloc.assumed_view("mastcam-z-200", 1648, 1200)


def test_a_camera_lists_fisheye_entries_have_grounds_from_their_labels():
    # The real data's list carries only the linear part of its two Hazcam (CAHVORE) entries;
    # their cameras come from the labels the entries name, as `tubeloc locate --rig` reads them.
    path = REPO.parent / "shared/data/real_mars/with_cameras/cameras.json"
    if not path.exists():
        pytest.skip(f"{path} is missing (../shared/data beside the repository)")
    entries = json.loads(path.read_text())
    fisheyes = [e for e in entries if e["model_type"] == "CAHVORE"]
    grounds = tubeloc.read_pds_grounds(path)
    assert len(grounds) == len(entries) and fisheyes
    for e in fisheyes:
        nx, ny, nz, d = grounds[e["image"].split("/")[-1]]
        # Level ground `camera_height_m` below the camera: n = up = -(site z) in the camera frame.
        up = [-row[2] for row in e["R_cam_from_site"]]
        assert (nx, ny, nz) == pytest.approx(up, abs=1e-9) and d == pytest.approx(-e["camera_height_m"], abs=1e-9)


def test_a_fisheye_entry_whose_label_is_missing_is_left_out_with_a_warning(tmp_path):
    entry = pds_entry()
    fisheye = pds_entry(image="images/RRB_2.jpg", model_type="CAHVORE", label_file="labels/RRB_2.LBL")
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps([entry, fisheye]))
    with pytest.warns(UserWarning, match=r"CAHVORE entry for \"RRB_2.jpg\".*RRB_2.LBL.*left out of the grounds"):
        grounds = tubeloc.read_pds_grounds(path)
    assert list(grounds) == ["NLB_1.jpg"]


def test_a_fisheye_label_gives_the_ground_of_its_linear_camera():
    # A Hazcam (CAHVORE) label as the list: the ground `tubeloc locate --rig LABEL` uses, the
    # same as the list's entry for that image.
    data = REPO.parent / "shared/data/real_mars/with_cameras"
    if not (data / "cameras.json").exists():
        pytest.skip(f"{data} is missing (../shared/data beside the repository)")
    entry = next(e for e in json.loads((data / "cameras.json").read_text()) if e["model_type"] == "CAHVORE")
    by_list = tubeloc.read_pds_grounds(data / "cameras.json")[entry["image"].split("/")[-1]]
    (by_label,) = tubeloc.read_pds_grounds(data / entry["label_file"]).values()
    assert by_label == pytest.approx(by_list, abs=1e-9)
