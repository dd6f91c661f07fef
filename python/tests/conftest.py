"""Shared fixtures: the `tubeloc` binary built from this workspace and the demo scene
(demo_scene.py)."""

import os
import subprocess
from pathlib import Path

import pytest
from demo_scene import make_demo_scene

REPO = Path(__file__).resolve().parents[2]


def tubeloc_binary() -> Path:
    """The CLI built by `cargo test --workspace --release` (TUBELOC_BIN overrides)."""
    if os.environ.get("TUBELOC_BIN"):
        return Path(os.environ["TUBELOC_BIN"])
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    return target / "release" / "tubeloc"


@pytest.fixture(scope="session")
def cli():
    exe = tubeloc_binary()
    if not exe.exists():
        if os.environ.get("CI"):
            pytest.fail(f"{exe} is missing: build it with cargo build --release -p tubeloc")
        pytest.skip(f"{exe} is missing (cargo build --release -p tubeloc)")

    def run(*args, check=True):
        p = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True, cwd=REPO)
        if check and p.returncode != 0:
            raise AssertionError(f"tubeloc {' '.join(map(str, args))} failed ({p.returncode}):\n{p.stderr}")
        return p

    return run


@pytest.fixture(scope="session")
def demo_scene(cli, tmp_path_factory):
    """(rig path, image path, ground string) of the demo scene."""
    return make_demo_scene(tubeloc_binary(), tmp_path_factory.mktemp("demo"))
