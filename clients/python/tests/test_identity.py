"""Byte identity with `perturb apply` (and `perturb detect`) on real KITTI data, every ID."""

import concurrent.futures
import json

import numpy as np
import pytest

import perturb
from conftest import read_png, run

SEED, SEQ = 7, 5
CAMERA = [e["id"] for e in perturb.catalogue("camera")]
LIDAR = [e["id"] for e in perturb.catalogue("lidar")]


def test_catalogue_lists_every_perturbation():
    entries = perturb.catalogue()
    assert len(CAMERA) == 42 and len(LIDAR) == 31 and len(entries) == 73
    rain = next(e for e in entries if e["id"] == "C-C7")
    assert rain["name"] == "rain" and rain["modality"] == "camera"
    assert rain["family"] == "weather" and rain["severities"] == [1, 2, 3, 4, 5]
    assert rain["description"] and rain["reference"]
    assert next(e for e in entries if e["id"] == "L-B1")["severities"] == [1, 2, 3]


def _cli_camera(cli, src, tmp, id_, severity):
    out = tmp / f"{id_}.png"
    run(cli, "apply", "--id", id_, "--severity", severity, "--seed", SEED, "--seq", SEQ, src, "-o", out)
    return read_png(out)


def test_every_camera_perturbation_matches_perturb_apply(cli, shared, frame, tmp_path):
    src = shared / "kitti_000008_mmdet3d" / "000008.png"
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        expected = dict(zip(CAMERA, pool.map(lambda i: _cli_camera(cli, src, tmp_path, i, 3), CAMERA)))
    for id_ in CAMERA:
        got = perturb.CameraPerturber(id_, 3, seed=SEED)(frame, seq=SEQ)
        assert got.dtype == np.uint8 and got.shape == frame.shape
        assert np.array_equal(got, expected[id_]), f"{id_} differs from perturb apply"
    # The frame is not all one perturbation's output: the comparison can fail.
    assert not np.array_equal(expected["C-C7"], frame)


def _cli_lidar(cli, src, tmp, id_, severity):
    out = tmp / f"{id_}.bin"
    run(cli, "apply", "--id", id_, "--severity", severity, "--seed", SEED, "--seq", SEQ, src, "-o", out)
    return out.read_bytes()


def test_every_lidar_perturbation_matches_perturb_apply(cli, scan_path, scan, tmp_path):
    # perturb apply reads a KITTI .bin with the HDL-64E model (KITTI's sensor, reflectance 0..1).
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        expected = dict(zip(LIDAR, pool.map(lambda i: _cli_lidar(cli, scan_path, tmp_path, i, 2), LIDAR)))
    changed = 0
    for id_ in LIDAR:
        got = perturb.LidarPerturber(id_, 2, seed=SEED, sensor="hdl64e")(scan, seq=SEQ)
        assert got.dtype == np.float32 and got.ndim == 2 and got.shape[1] == 4
        assert got.tobytes() == expected[id_], f"{id_} differs from perturb apply"
        changed += got.shape != scan.shape or not np.array_equal(got, scan)
    assert changed >= 25, f"only {changed} of {len(LIDAR)} perturbations changed the scan"


def test_extra_columns_are_carried_through(scan):
    ring = (np.arange(len(scan)) % 64).astype(np.float32)
    tagged = np.column_stack([scan, ring, ring * 2]).astype(np.float32)
    for id_ in ("L-B1", "L-C1", "L-F4"):
        plain = perturb.LidarPerturber(id_, 2, seed=1, sensor="hdl64e")(scan, seq=2)
        both = perturb.LidarPerturber(id_, 2, seed=1, sensor="hdl64e")(tagged, seq=2)
        assert both.shape == (plain.shape[0], 6)
        assert np.array_equal(both[:, :4], plain)
        assert np.array_equal(both[:, 5], both[:, 4] * 2), "extra columns stay with their point"


def _same_detections(got, expected):
    assert len(expected) > 3 and len(got) == len(expected)
    for g, e in zip(got, expected):
        assert set(g) == set(e) == {"center", "size", "yaw", "class", "points"}
        np.testing.assert_allclose(g["center"], e["center"], rtol=0, atol=1e-5)
        np.testing.assert_allclose(g["size"], e["size"], rtol=0, atol=1e-5)
        assert abs(g["yaw"] - e["yaw"]) < 1e-6
        assert g["points"] == e["points"] and g["class"] == e["class"]


def test_detect_matches_perturb_detect(cli, scan_path, scan):
    # perturb detect reads a KITTI .bin as the HDL-64E (the detector's radii follow its beams).
    expected = json.loads(run(cli, "detect", scan_path, "--json").stdout)
    _same_detections(perturb.detect(scan, sensor="hdl64e"), expected)
    assert any(e["class"] == "vehicle" for e in expected)
    objects = json.loads(run(cli, "detect", scan_path, "--json", "--objects").stdout)
    assert len(perturb.detect(scan, objects=True, sensor="hdl64e")) == len(objects)
    vehicles = json.loads(run(cli, "detect", scan_path, "--json", "--class", "vehicle").stdout)
    _same_detections(perturb.detect(scan, class_="vehicle", sensor="hdl64e"), vehicles)


def _turned(scan):
    """The scan in nuScenes' convention (x right, y forward): (x, y, z) -> (-y, x, z)."""
    out = scan.copy()
    out[:, 0], out[:, 1] = -scan[:, 1], scan[:, 0]
    return out


def test_a_y_forward_cloud_gives_the_bytes_of_perturb_apply(cli, shared, scan, tmp_path):
    # Issue 33: without a forward axis, 21 LiDAR ids differed from perturb apply on a y-forward
    # cloud at every severity. The shared scan turned 90 degrees, read as looking along +y.
    turned = _turned(scan)
    src = tmp_path / "turned.bin"
    turned.tofile(src)

    def cli_out(id_):
        out = tmp_path / f"{id_}.bin"
        run(cli, "apply", "--id", id_, "--severity", 2, "--seed", SEED, "--seq", SEQ,
            "--forward", "+y", src, "-o", out)
        return out.read_bytes()

    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        expected = dict(zip(LIDAR, pool.map(cli_out, LIDAR)))
    for id_ in LIDAR:
        p = perturb.LidarPerturber(id_, 2, seed=SEED, sensor="hdl64e", forward="+y")
        assert p.forward == "+y"
        assert p(turned, seq=SEQ).tobytes() == expected[id_], f"{id_} differs from perturb apply"
    # The sensor's front is +y: on a whole 360-degree scan the field-of-view filter keeps the
    # points ahead (y > 0), the same points it keeps of the original scan ahead along +x (without
    # the forward axis it kept the sensor's right-hand side).
    full = np.fromfile(shared / "kitti" / "velodyne" / "000000.bin", dtype="<f4").reshape(-1, 4)
    fov = perturb.LidarPerturber("L-B6", 3, seed=SEED, sensor="hdl64e", forward="+y")(_turned(full))
    plain = perturb.LidarPerturber("L-B6", 3, seed=SEED, sensor="hdl64e")(full)
    assert np.array_equal(fov, _turned(plain))
    assert (fov[:, 1] > 0).mean() > 0.99 and len(fov) < 0.5 * len(full)
    # The detector's boxes, in the cloud's own frame, with their class.
    boxes = json.loads(run(cli, "detect", src, "--json", "--forward", "+y").stdout)
    _same_detections(perturb.detect(turned, sensor="hdl64e", forward="+y"), boxes)
