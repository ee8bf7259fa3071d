"""The array API: errors, strides, copies, in-place, threads (synthetic frames, no data needed)."""

import concurrent.futures

import numpy as np
import pytest

import perturb
from perturb import _perturb


def test_errors_are_perturb_errors_with_the_core_message(small):
    with pytest.raises(perturb.PerturbError, match="C-Z9"):
        perturb.CameraPerturber("C-Z9", 1)
    with pytest.raises(ValueError, match=r"severity 9 is out of range for L-B1: valid severities are 1..=3"):
        perturb.LidarPerturber("L-B1", 9)
    with pytest.raises(perturb.PerturbError, match=r"severity 300 is out of range for C-A1"):
        perturb.CameraPerturber("C-A1", 300)
    with pytest.raises(perturb.PerturbError, match="lidar"):
        perturb.CameraPerturber("L-A9", 1)
    with pytest.raises(perturb.PerturbError, match="sensor"):
        perturb.LidarPerturber("L-A9", 1, sensor="hdl99")
    with pytest.raises(ValueError, match="unknown perturbation"):
        perturb.CameraPerturber("C-Z9", 1)
    p = perturb.CameraPerturber("C-C7", 2)
    with pytest.raises(perturb.PerturbError, match=r"uint8.*got dtype float32"):
        p(small.astype(np.float32))
    with pytest.raises(perturb.PerturbError, match=r"got shape \(48, 64, 2\)"):
        p(small[:, :, :2])
    with pytest.raises(perturb.PerturbError, match=r"got shape \(48,\)"):
        p(small[:, 0, 0])
    with pytest.raises(perturb.PerturbError, match="format bgr8 has 3 channels but the array has 4"):
        p(np.zeros((4, 4, 4), np.uint8), format="bgr8")
    lidar = perturb.LidarPerturber("L-B1", 1)
    with pytest.raises(perturb.PerturbError, match=r"float32.*got dtype float64"):
        lidar(np.zeros((10, 4)))
    with pytest.raises(perturb.PerturbError, match=r"got shape \(10, 2\)"):
        lidar(np.zeros((10, 2), np.float32))
    with pytest.raises(perturb.PerturbError, match="fields names 3 columns but the array has 4"):
        perturb.LidarPerturber("L-B1", 1, fields=["x", "y", "z"])(np.zeros((3, 4), np.float32))
    assert issubclass(perturb.PerturbError, ValueError)


def test_names_and_ids_and_properties():
    p = perturb.CameraPerturber("rain", 3, seed=4)
    assert (p.id, p.name, p.severity, p.seed) == ("C-C7", "rain", 3, 4)
    q = perturb.LidarPerturber("L-A9", 2, sensor="vlp16")
    assert (q.id, q.name, q.sensor) == ("L-A9", "fog_fast", "VLP-16")
    assert "C-C7" in repr(p) and "L-A9" in repr(q)
    assert isinstance(perturb.perturber("fog_fast", 1), perturb.LidarPerturber)
    assert isinstance(perturb.perturber("C-A1", 1), perturb.CameraPerturber)


def test_output_depends_on_seed_and_seq_only(small):
    p = perturb.CameraPerturber("C-A1", 3, seed=1)
    a, b = p(small, 1), p(small, 1)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, p(small, 2)), "seq changes the noise"
    assert not np.array_equal(a, perturb.CameraPerturber("C-A1", 3, seed=2)(small, 1))
    assert not np.array_equal(a, small)


def test_strided_views_are_read_in_place_or_copied_and_give_the_same_bytes(small):
    p = perturb.CameraPerturber("C-C7", 3, seed=9)
    big = np.random.default_rng(0).integers(0, 256, (100, 120, 3), dtype=np.uint8)
    crop = big[10:70, 20:100]                      # row stride 360, pixels packed: no copy
    assert not crop.flags.c_contiguous and not _perturb.input_is_copied(crop)
    assert np.array_equal(p(crop, 2), p(np.ascontiguousarray(crop), 2))
    bgr = big[:, :, ::-1]                          # channel stride -1: copied first
    assert _perturb.input_is_copied(bgr)
    assert np.array_equal(p(bgr, 2), p(np.ascontiguousarray(bgr), 2))
    fortran = np.asfortranarray(big)
    assert _perturb.input_is_copied(fortran)
    assert np.array_equal(p(fortran, 2), p(big, 2))
    flipped = big[::-1]                            # negative row stride: copied
    assert _perturb.input_is_copied(flipped)
    assert np.array_equal(p(flipped, 2), p(np.ascontiguousarray(flipped), 2))
    assert not _perturb.input_is_copied(big)
    mono = big[:, :, 0]                            # pixel stride 3: copied
    assert _perturb.input_is_copied(mono)
    assert np.array_equal(p(mono, 1), p(np.ascontiguousarray(mono), 1))
    cloud = np.random.default_rng(1).normal(size=(500, 6)).astype(np.float32) * 10
    view = cloud[:, :4]
    assert _perturb.input_is_copied(view, cloud=True)
    assert not _perturb.input_is_copied(cloud, cloud=True)
    q = perturb.LidarPerturber("L-C1", 2, seed=3)
    assert np.array_equal(q(view, 1), q(np.ascontiguousarray(view), 1))


def test_bgr_format_is_the_rgb_result_with_channels_swapped(small):
    p = perturb.CameraPerturber("C-F1", 4, seed=2)   # false colour: channel order matters
    rgb = p(small, 0)
    bgr = p(np.ascontiguousarray(small[:, :, ::-1]), 0, format="bgr8")
    assert np.array_equal(bgr[:, :, ::-1], rgb)


def test_call_copies_and_apply_works_in_place(small):
    p = perturb.CameraPerturber("C-B3", 3, seed=5)
    before = small.copy()
    out = p(small, 4)
    assert np.array_equal(small, before), "__call__ leaves its input alone"
    assert out is not small and not np.shares_memory(out, small)
    inplace = small.copy()
    ret = p.apply_(inplace, 4)
    assert ret is inplace and np.array_equal(inplace, out)
    # A row-strided view is perturbed in place without touching its surroundings.
    big = np.zeros((80, 90, 3), np.uint8)
    big[10:58, 5:69] = small
    p.apply_(big[10:58, 5:69], 4)
    assert np.array_equal(big[10:58, 5:69], out)
    assert not big[:10].any() and not big[58:].any() and not big[:, :5].any() and not big[:, 69:].any()
    # Strides the core cannot address in place (channel-reversed view): still correct.
    swapped = small[:, :, ::-1].copy()
    view = swapped[:, :, ::-1]
    p.apply_(view, 4)
    assert np.array_equal(view, out)
    frozen = small.copy()
    frozen.setflags(write=False)
    with pytest.raises(perturb.PerturbError, match="not writable"):
        p.apply_(frozen, 4)


def test_threads_share_a_perturber_and_get_the_sequential_bytes(small):
    frames = [np.roll(small, k, axis=1) for k in range(6)]
    cam = perturb.CameraPerturber("C-C3", 3, seed=11)
    lidar = perturb.LidarPerturber("L-A9", 2, seed=11)
    cloud = np.random.default_rng(2).normal(size=(4000, 4)).astype(np.float32) * 20
    expected = [cam(f, k) for k, f in enumerate(frames)]
    expected_l = [lidar(cloud, k) for k in range(6)]
    jobs = [(k % 6) for k in range(48)]
    with concurrent.futures.ThreadPoolExecutor(4) as pool:
        got = list(pool.map(lambda k: cam(frames[k], k), jobs))
        got_l = list(pool.map(lambda k: lidar(cloud, k), jobs))
    for k, g in zip(jobs, got):
        assert np.array_equal(g, expected[k])
    for k, g in zip(jobs, got_l):
        assert g.tobytes() == expected_l[k].tobytes()


_ONE_CORE = r"""
import concurrent.futures, os, sys
import numpy as np
os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
import perturb  # rayon sizes its pool now: one thread
frame = np.load(sys.argv[1])
ids = [e["id"] for e in perturb.catalogue() if e["modality"] == "camera"]
def run(i):
    return perturb.CameraPerturber(i, 1, seed=5)(frame, 3)
with concurrent.futures.ThreadPoolExecutor(3) as pool:  # each thread its own inline pool
    outs = list(pool.map(run, ids))
np.savez(sys.argv[2], **dict(zip(ids, outs)))
"""


def test_on_one_core_the_work_runs_inline_with_the_same_bytes(tmp_path):
    """With one core allowed, a call runs the perturbation's parallel loops on the calling
    thread (no hand-off to rayon's pool): the bytes are those of the multi-core path."""
    import subprocess
    import sys

    rng = np.random.default_rng(9)
    frame = rng.integers(0, 256, size=(160, 200, 3), dtype=np.uint8)
    np.save(tmp_path / "frame.npy", frame)
    subprocess.run(
        [sys.executable, "-c", _ONE_CORE, str(tmp_path / "frame.npy"), str(tmp_path / "out.npz")],
        check=True,
    )
    got = np.load(tmp_path / "out.npz")
    ids = [e["id"] for e in perturb.catalogue() if e["modality"] == "camera"]
    assert sorted(got.files) == sorted(ids)
    for i in ids:
        want = perturb.CameraPerturber(i, 1, seed=5)(frame, 3)
        assert np.array_equal(got[i], want), i


def test_every_bad_argument_raises_perturb_error_naming_it(small):
    """Issue 33: severity 2**70, 3.0 or '3' and a negative seed raised OverflowError/TypeError."""
    cloud = np.zeros((10, 4), np.float32)
    cases = [
        (lambda: perturb.CameraPerturber("C-C7", 2**70), r"severity 1180591620717411303424 is out of range"),
        (lambda: perturb.CameraPerturber("C-C7", 3.0), r"severity must be an integer, got float 3.0"),
        (lambda: perturb.CameraPerturber("C-C7", "3"), r"severity must be an integer, got str '3'"),
        (lambda: perturb.CameraPerturber("C-C7", True), r"severity must be an integer, got bool"),
        (lambda: perturb.CameraPerturber("C-C7", 3, seed=-1), r"seed must be an integer in 0..2\*\*64, got -1"),
        (lambda: perturb.CameraPerturber("C-C7", 3, seed=2**64), r"seed must be an integer in 0..2\*\*64"),
        (lambda: perturb.CameraPerturber("C-C7", 3, seed=0.5), r"seed must be an integer, got float"),
        (lambda: perturb.CameraPerturber("C-C7", 3)(small, -1), r"seq must be an integer in 0..2\*\*64, got -1"),
        (lambda: perturb.CameraPerturber("C-C7", 3)(small, 2.0), r"seq must be an integer, got float"),
        (lambda: perturb.CameraPerturber("C-C7", 3).apply_(small.copy(), "1"), r"seq must be an integer, got str"),
        (lambda: perturb.CameraPerturber("C-C7", 3)(small, format=3), r"format must be a str, got int"),
        (lambda: perturb.LidarPerturber("L-B1", 2**70), r"severity .* is out of range for L-B1"),
        (lambda: perturb.LidarPerturber("L-B1", 1, seed=-5), r"seed must be an integer in 0..2\*\*64, got -5"),
        (lambda: perturb.LidarPerturber("L-B1", 1, sensor=7), r"sensor must be a str, got int"),
        (lambda: perturb.LidarPerturber("L-B1", 1, forward="up"), r"forward: .*`up` is not an axis"),
        (lambda: perturb.LidarPerturber("L-B1", 1, forward="+z"), r"forward"),
        (lambda: perturb.LidarPerturber("L-B1", 1, intensity_max="x"), r"intensity_max must be a number"),
        (lambda: perturb.LidarPerturber("L-B1", 1, intensity_max=3), r"intensity.max must be 1 or 255"),
        (lambda: perturb.LidarPerturber("L-B1", 1, fields="xyz"), r"fields must be a list of str"),
        (lambda: perturb.LidarPerturber("L-B1", 1)(cloud, -2), r"seq must be an integer in 0..2\*\*64"),
        (lambda: perturb.detect(cloud, objects=1), r"objects must be True or False, got int 1"),
        (lambda: perturb.detect(cloud, class_="tram"), r"class_: .*unknown object class `tram`"),
        (lambda: perturb.detect(cloud, forward="-q"), r"forward"),
        (lambda: perturb.apply_encoded(b"\0" * 12, "mono8", 4, 3, 4, "C-A1", 9.5), r"severity must be an integer"),
        (lambda: perturb.perturber(5, 1), r"id must be a str"),
        (lambda: perturb.perturber("C-C7", 1, sensor="hdl64e"), r"camera perturbation: the LiDAR options"),
    ]
    for call, message in cases:
        with pytest.raises(perturb.PerturbError, match=message):
            call()


def test_help_shows_the_real_signatures():
    """Issue 33: help() showed __call__(*args, **kwargs)."""
    import inspect
    import pydoc

    sig = lambda f: str(inspect.signature(f))  # noqa: E731
    assert "seq: int = 0, *, format" in sig(perturb.CameraPerturber.__call__)
    assert sig(perturb.CameraPerturber.apply_) == "(self, image, seq=0, *, format=None)"
    assert "(self, points: Any, seq: int = 0)" in sig(perturb.LidarPerturber.__call__)
    assert "forward: Optional[str] = None" in sig(perturb.LidarPerturber)
    assert "sensor=None, forward=None" in sig(perturb.detect)
    text = pydoc.render_doc(perturb.LidarPerturber, renderer=pydoc.plaintext)
    assert "__call__(self, points: Any, seq: int = 0)" in text and "*args" not in text
