"""Errors raise `tubeloc.TubelocError` (a ValueError) with the message the CLI prints."""

import numpy as np
import pytest

import tubeloc


def cli_error(cli, *args):
    p = cli(*args, check=False)
    assert p.returncode == 1, p.stderr
    last = p.stderr.strip().splitlines()[-1]
    assert last.startswith("error: "), p.stderr
    return last[len("error: "):]


def raised(fn, *args, **kwargs):
    with pytest.raises(tubeloc.TubelocError) as e:
        fn(*args, **kwargs)
    return str(e.value)


def test_tubeloc_error_is_a_value_error():
    assert issubclass(tubeloc.TubelocError, ValueError)


@pytest.mark.parametrize(
    "cli_args, py_kwargs",
    [
        (["--model", "/nonexistent/tubenet.safetensors"], {"model": "/nonexistent/tubenet.safetensors"}),
        (["--camera-name", "nope"], {"camera": "nope"}),
        (["--detector", "line2d", "--templates", "/nonexistent/lib.tlt"], {"detector": "line2d", "templates": "/nonexistent/lib.tlt"}),
        (["--detector", "fused", "--templates", "/nonexistent/lib.tlt"], {"detector": "fused", "templates": "/nonexistent/lib.tlt"}),
        (["--calibration", "/nonexistent/cal.json"], {"calibration": "/nonexistent/cal.json"}),
    ],
    ids=["missing-model", "camera-name", "line2d-missing-templates", "fused-missing-templates", "missing-calibration"],
)
def test_locator_errors_carry_the_cli_message(cli, demo_scene, tmp_path, cli_args, py_kwargs):
    rig, image, _ = demo_scene
    expected = cli_error(cli, "locate", "--rig", rig, "--image", image, "--out", tmp_path / "p.json", *cli_args)
    assert raised(tubeloc.Locator, str(rig), **py_kwargs) == expected


@pytest.mark.parametrize("band", ["4:1", "near:4"])
def test_range_band_errors_carry_the_cli_message(cli, demo_scene, tmp_path, band):
    # The CLI checks --range-m when it parses the command line (exit 2, clap's framing around
    # the same message).
    rig, image, _ = demo_scene
    p = cli("locate", "--rig", rig, "--image", image, "--out", tmp_path / "p.json", "--range-m", band, check=False)
    assert p.returncode == 2, p.stderr
    message = raised(tubeloc.Locator, str(rig), range_m=band)
    assert message.startswith(f'--range-m "{band}": '), message
    assert message in p.stderr, (message, p.stderr)


def test_missing_rig_file_carries_the_cli_message(cli, demo_scene, tmp_path):
    _, image, _ = demo_scene
    missing = tmp_path / "no_rig.json"
    expected = cli_error(cli, "locate", "--rig", missing, "--image", image, "--out", tmp_path / "p.json")
    assert raised(tubeloc.Locator, str(missing)) == expected
    assert raised(tubeloc.read_rig, str(missing)) == expected


def test_bad_ground_carries_the_cli_parser_message(cli, demo_scene, tmp_path):
    rig, image, _ = demo_scene
    p = cli("locate", "--rig", rig, "--image", image, "--out", tmp_path / "p.json", "--ground", "0,-1,0,1.5", check=False)
    assert p.returncode == 2  # a command-line error, from the same parser
    locator = tubeloc.Locator(str(rig))
    msg = raised(locator.locate, tubeloc.read_image(image), ground="0,-1,0,1.5")
    assert msg in p.stderr
    assert msg.startswith('invalid ground: "0,-1,0,1.5": d = 1.5 puts the camera on or below the ground')


def test_image_of_the_wrong_size_names_the_camera(demo_scene):
    rig, _, _ = demo_scene
    locator = tubeloc.Locator(str(rig))
    w, h = tubeloc.read_rig(rig).image_size("demo")
    msg = raised(locator.locate, np.zeros((40, 60, 3), np.uint8))
    assert msg == f'the image is 60x40 but rig camera "demo" is {w}x{h}'
