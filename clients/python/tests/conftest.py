"""Shared fixtures: the workspace's `perturb` binary, the real data in ../shared/data, numpy images."""

import os
import pathlib
import subprocess

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]
SHARED = ROOT.parent / "shared" / "data"


def _missing(what: str):
    """Skips the test, or fails it under CI=true (CI must run every test)."""
    if os.environ.get("CI") == "true":
        pytest.fail(f"{what} is missing and CI=true")
    pytest.skip(f"{what} is missing", allow_module_level=True)


def need(module: str, install: str):
    """Imports `module`, or skips the test (fails it under CI=true) naming how to install it."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        _missing(f"{module} ({install})")


@pytest.fixture(scope="session")
def cli() -> pathlib.Path:
    """The workspace's `perturb` binary (PERTURB_CLI, default target/debug/perturb)."""
    path = pathlib.Path(os.environ.get("PERTURB_CLI", ROOT / "target" / "debug" / "perturb"))
    if not path.exists():
        pytest.fail(f"{path} is missing: build it first (cargo build --workspace --bins)")
    return path


@pytest.fixture(scope="session")
def shared() -> pathlib.Path:
    """../shared/data (skips the test when it is absent, fails under CI=true)."""
    if not (SHARED / "kitti").is_dir():
        _missing(f"the recorded data {SHARED}")
    return SHARED


def run(*args) -> subprocess.CompletedProcess:
    """Runs a command and fails the test with its stderr if it fails."""
    p = subprocess.run([str(a) for a in args], capture_output=True)
    assert p.returncode == 0, f"{args} failed:\n{p.stderr.decode(errors='replace')}"
    return p


def read_png(path) -> np.ndarray:
    """An RGB8 (or mono8) PNG as an HxWx3 (HxW) uint8 array (PNG is lossless: any decoder)."""
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im).copy()


@pytest.fixture(scope="session")
def frame(shared) -> np.ndarray:
    """KITTI 000008's camera frame, HxWx3 uint8."""
    return read_png(shared / "kitti_000008_mmdet3d" / "000008.png")


@pytest.fixture(scope="session")
def scan_path(shared) -> pathlib.Path:
    """KITTI 000008's reduced velodyne scan (17,238 points, x, y, z, reflectance)."""
    return shared / "kitti_000008_mmdet3d" / "000008_velodyne_reduced.bin"


@pytest.fixture(scope="session")
def scan(scan_path) -> np.ndarray:
    """The scan as an (N, 4) float32 array."""
    return np.fromfile(scan_path, dtype="<f4").reshape(-1, 4)


@pytest.fixture
def small():
    """A small synthetic RGB frame (no recorded data needed)."""
    rng = np.random.default_rng(3)
    return rng.integers(0, 256, size=(48, 64, 3), dtype=np.uint8)
