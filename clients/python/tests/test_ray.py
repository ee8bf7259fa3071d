"""Ray: a local cluster on 127.0.0.1 (dashboard off), perturb_dataset and run_batch == perturb batch."""

import filecmp
import json
import os
import shutil
import tempfile

import numpy as np
import pytest

import perturb
from conftest import need, read_png, run

ray = need("ray", "pip install 'ray[data]'")
import perturb.ray as pray  # noqa: E402


@pytest.fixture(scope="module")
def cluster():
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    # Ray puts unix sockets under its temp dir, whose paths may not exceed 107 bytes: a short
    # folder in the system's temp dir, not pytest's (which lives under the target folder).
    temp = tempfile.mkdtemp(prefix="perturb-ray-")
    ray.init(
        num_cpus=2,
        _node_ip_address="127.0.0.1",
        include_dashboard=False,
        object_store_memory=200 * 1024 * 1024,
        _temp_dir=temp,
        log_to_driver=False,
        configure_logging=False,
    )
    ray.data.DataContext.get_current().enable_progress_bars = False
    yield
    ray.shutdown()
    shutil.rmtree(temp, ignore_errors=True)


def _tree(root):
    """Relative path -> bytes of every file under root."""
    out = {}
    for dirpath, _, names in os.walk(root):
        for n in names:
            p = os.path.join(dirpath, n)
            out[os.path.relpath(p, root)] = open(p, "rb").read()
    return out


def test_perturb_dataset_rows_per_pair(cluster, small):
    frames = [np.roll(small, k, axis=1) for k in range(3)]
    ds = ray.data.from_items([{"image": f, "seq": k, "name": f"f{k}"} for k, f in enumerate(frames)])
    rows = pray.perturb_dataset(ds, ["C-A1", "rain"], [1, 4], seed=2, batch_size=2).take_all()
    assert len(rows) == 3 * 4
    seen = set()
    for r in rows:
        k = int(r["name"][1:])
        assert r["seq"] == k
        expected = perturb.CameraPerturber(r["id"], r["severity"], seed=2)(frames[k], k)
        assert np.array_equal(r["image"], expected)
        seen.add((r["name"], r["id"], int(r["severity"])))
    assert len(seen) == 12 and {i for _, i, _ in seen} == {"C-A1", "C-C7"}


def test_perturb_dataset_of_clouds(cluster, scan):
    clouds = [scan[: 4000 + 1000 * k] for k in range(2)]
    ds = ray.data.from_items([{"points": c, "seq": k} for k, c in enumerate(clouds)])
    rows = pray.perturb_dataset(ds, ["L-B1"], [1, 3], seed=4, sensor="hdl64e", concurrency=1).take_all()
    assert len(rows) == 4
    for r in rows:
        p = perturb.LidarPerturber("L-B1", r["severity"], seed=4, sensor="hdl64e")
        expected = p(clouds[r["seq"]], r["seq"])
        assert r["points"].shape == expected.shape and np.array_equal(r["points"], expected)
        assert r["points"].shape[0] < len(clouds[r["seq"]])


def test_run_batch_equals_perturb_batch_on_any_number_of_actors_and_resumes(cluster, cli, shared, tmp_path):
    images = shared / "kitti" / "image_2"
    args = ["--id", "C-A1", "--id", "C-C7", "--severity", "1", "--severity", "3", "--seed", "5"]
    run(cli, "batch", images, "--out", tmp_path / "cli", "--quiet", *args)
    kw = dict(ids=["C-A1", "C-C7"], severities=[1, 3], seed=5)
    one = pray.run_batch(images, tmp_path / "one", concurrency=1, batch_size=1, **kw)
    two = pray.run_batch(images, tmp_path / "two", concurrency=2, batch_size=3, **kw)
    assert one == two == {"sets": 4, "resumed": 0, "files": 2, "written": 8}
    cli_tree = _tree(tmp_path / "cli")
    assert len(cli_tree) == 4 * 3 + 1  # 2 images + .done per set, and batch.json
    assert _tree(tmp_path / "one") == cli_tree
    assert _tree(tmp_path / "two") == cli_tree
    assert json.loads(cli_tree["batch.json"])["sets"] == ["C-A1:1", "C-A1:3", "C-C7:1", "C-C7:3"]
    # Resume: one set unfinished with one file missing; only that file is written again.
    s = tmp_path / "two" / "C-C7_rain" / "s3"
    (s / ".done").unlink()
    (s / "000001.png").unlink()
    again = pray.run_batch(images, tmp_path / "two", concurrency=2, **kw)
    assert again == {"sets": 4, "resumed": 3, "files": 2, "written": 1}
    assert _tree(tmp_path / "two") == cli_tree


def test_run_batch_of_scans_with_a_shard(cluster, cli, shared, tmp_path):
    scans = tmp_path / "scans"
    scans.mkdir()
    shutil.copy(shared / "kitti_000008_mmdet3d" / "000008_velodyne_reduced.bin", scans / "a.bin")
    args = ["--id", "L-B1", "--id", "L-A9", "--severity", "2", "--severity", "3", "--seed", "1"]
    run(cli, "batch", scans, "--out", tmp_path / "cli", "--quiet", "--shard", "1/2", *args)
    got = pray.run_batch(scans, tmp_path / "ray", ids=["L-B1", "L-A9"], severities=[2, 3], seed=1, shard="1/2")
    assert got["sets"] == 2 and got["written"] == 2
    assert _tree(tmp_path / "ray") == _tree(tmp_path / "cli")
    manifest = json.loads((tmp_path / "ray" / "batch.json").read_text())
    assert manifest["shard"] == "1/2" and manifest["sets"] == ["L-A9:3", "L-B1:3"]


def test_run_batch_refuses_a_bag(cluster, shared, tmp_path):
    with pytest.raises(perturb.PerturbError, match="is a bag"):
        pray.run_batch(shared / "ros2_mcap_kitti_000001", tmp_path / "o", ids=["C-A1"])
