"""Perturbations on Ray Data: datasets of arrays, and ``perturb batch`` on a Ray cluster.

Two entry points, both ``map_batches`` over an actor pool (each actor keeps one perturber per
(ID, severity) of the grid, built once):

- :func:`perturb_dataset` turns a Dataset of ``image`` (or ``points``) rows into one row per
  (row, ID, severity), with ``id`` and ``severity`` columns added and the perturbed array in the
  same column. The sequence number of a row is its ``seq`` column (0 without one).
- :func:`run_batch` is ``perturb batch`` over a folder of images or point clouds on Ray: the same
  folder layout (``OUT/<ID>_<name>/s<N>/<file>``), the same manifest (``OUT/batch.json``), the same
  bytes (file *k* in sorted order has sequence number *k*), the same ``.done`` markers, so a run is
  resumable and can be finished by ``perturb batch`` (and the other way round). The result does
  not depend on the number of actors.

On a laptop ``ray.init()`` starts a local cluster; on a cluster, ``ray.init(address="auto")`` (or
``address="ray://head:10001"``) runs the same code over every node, with no other change: the
actors then need the ``perturb`` package installed on every node and, for :func:`run_batch`, the
input and output folders on a file system every node sees (NFS, a shared mount).
"""

from __future__ import annotations

import os
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from . import CameraPerturber, LidarPerturber, _perturb
from ._perturb import PerturbError

__all__ = ["perturb_dataset", "run_batch", "grid"]


def _ray():
    try:
        import ray  # noqa: F401
        import ray.data  # noqa: F401
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("perturb.ray needs Ray Data: pip install 'ray[data]'") from e
    return ray


def _pool(concurrency: int):
    """An actor pool of exactly `concurrency` actors."""
    ray = _ray()
    if concurrency < 1:
        raise ValueError(f"concurrency must be at least 1, not {concurrency}")
    return ray.data.ActorPoolStrategy(size=concurrency)


def grid(ids: Iterable[str], severities: Iterable[int]) -> List[Tuple[str, int]]:
    """The (ID, severity) pairs of ``ids`` x ``severities``, IDs normalised, severities outside a
    perturbation's range left out (as ``perturb batch`` does); unknown IDs raise PerturbError."""
    entries = {e["id"]: e for e in _perturb.catalogue()}
    by_name = {}
    for e in entries.values():
        by_name.setdefault(e["name"].lower(), e)
    if isinstance(ids, str):
        raise PerturbError(f"ids must be a list of IDs or names, got the str {ids!r}")
    sevs = list(severities)
    for s in sevs:
        if not isinstance(s, int) or isinstance(s, bool):
            raise PerturbError(f"severities must be integers, got {type(s).__name__} {s!r}")
    out = []
    for i in ids:
        if not isinstance(i, str):
            raise PerturbError(f"ids must be IDs or names (str), got {type(i).__name__} {i!r}")
        e = entries.get(i.upper()) or by_name.get(i.lower())
        if e is None:
            raise PerturbError(f"unknown perturbation `{i}` (see perturb.catalogue())")
        for s in sevs:
            if s in e["severities"]:
                out.append((e["id"], int(s)))
    if not out:
        raise PerturbError(f"no (id, severity) pair: severities {sevs} fit none of {list(ids)}")
    return out


def _column(value: List[Any]) -> np.ndarray:
    """A column of a numpy batch: stacked when every value has one shape, else an object array
    (Ray stores that as a variable-shaped tensor column)."""
    if value and isinstance(value[0], np.ndarray):
        if all(v.shape == value[0].shape for v in value):
            return np.stack(value)
        col = np.empty(len(value), dtype=object)
        col[:] = value
        return col
    return np.asarray(value)


class _PerturbRows:
    """Ray actor: one perturber per (ID, severity), each row out once per pair."""

    def __init__(self, pairs, seed, column, lidar_options, image_format):
        self.column = column
        self.format = image_format
        self.perturbers = {}
        for id_, sev in pairs:
            entry = next(e for e in _perturb.catalogue() if e["id"] == id_)
            if entry["modality"] == "lidar":
                self.perturbers[(id_, sev)] = LidarPerturber(id_, sev, seed, **lidar_options)
            else:
                self.perturbers[(id_, sev)] = CameraPerturber(id_, sev, seed)

    def __call__(self, batch: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
        col = self.column or ("image" if "image" in batch else "points")
        if col not in batch:
            raise PerturbError(
                f"the dataset has no `{col}` column (columns: {sorted(batch)}); name it with column="
            )
        rows = len(batch[col])
        seqs = batch.get("seq")
        out: Dict[str, List[Any]] = {k: [] for k in batch}
        out["id"], out["severity"] = [], []
        for i in range(rows):
            value = np.asarray(batch[col][i])
            seq = int(seqs[i]) if seqs is not None else 0
            for (id_, sev), p in self.perturbers.items():
                for k in batch:
                    if k != col:
                        out[k].append(batch[k][i])
                if isinstance(p, CameraPerturber):
                    out[col].append(p(value, seq, format=self.format))
                else:
                    out[col].append(p(value, seq))
                out["id"].append(id_)
                out["severity"].append(sev)
        return {k: _column(v) for k, v in out.items()}


def perturb_dataset(
    ds,
    ids: Sequence[str],
    severities: Sequence[int],
    seed: int = 0,
    *,
    column: Optional[str] = None,
    sensor: Optional[str] = None,
    intensity_max: Optional[float] = None,
    fields: Optional[Sequence[str]] = None,
    format: Optional[str] = None,
    forward: Optional[str] = None,
    batch_size: int = 8,
    concurrency: int = 2,
):
    """Perturbs every row of a Ray Dataset with every (ID, severity) of ``ids`` x ``severities``.

    Rows hold an ``image`` (HxWx3 / HxW uint8) or ``points`` ((N, k) float32) column (or the one
    named by ``column``) and optionally ``seq`` (the frame sequence number, default 0). Each row
    comes out once per pair, with ``id`` and ``severity`` columns and the perturbed array in place
    of the input; other columns are carried along. ``sensor``, ``intensity_max``, ``forward``
    (the axis the clouds' frame looks along, ``+x`` by default) and ``fields`` configure LiDAR
    perturbers as for :class:`perturb.LidarPerturber`, ``format`` the pixel order of images
    (``bgr8``). Lazy, like every
    Ray Dataset transformation. ``batch_size`` rows go to an actor at a time; ``concurrency``
    actors run (each with its own perturbers).
    """
    pairs = grid(ids, severities)
    lidar_options = {"sensor": sensor, "intensity_max": intensity_max, "forward": forward}
    if fields is not None:
        lidar_options["fields"] = list(fields)
    # Built once here, so that a bad option raises now (naming it), not in an actor.
    for id_, sev in pairs:
        if next(e for e in _perturb.catalogue() if e["id"] == id_)["modality"] == "lidar":
            LidarPerturber(id_, sev, seed, **lidar_options)
            break
    return ds.map_batches(
        _PerturbRows,
        fn_constructor_kwargs=dict(
            pairs=pairs, seed=seed, column=column, lidar_options=lidar_options, image_format=format
        ),
        batch_size=batch_size,
        batch_format="numpy",
        compute=_pool(concurrency),
    )


class _WriteFiles:
    """Ray actor: the per-file worker of ``perturb batch`` (one perturber per (ID, severity))."""

    def __init__(self, root, first_file, seed, sensor, intensity_max, forward):
        self.worker = _perturb.BatchWorker(root, first_file, seed, sensor, intensity_max, forward)

    def __call__(self, batch: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
        written = [
            self.worker.run(str(rel), int(seq), str(id_), int(sev), str(d))
            for rel, seq, id_, sev, d in zip(
                batch["file"], batch["seq"], batch["id"], batch["severity"], batch["dir"]
            )
        ]
        return {"dir": batch["dir"], "written": np.asarray(written, dtype=bool)}


def run_batch(
    input: os.PathLike | str,
    out: os.PathLike | str,
    *,
    ids: Sequence[str] = (),
    families: Sequence[str] = (),
    modality: Optional[str] = None,
    severities: Sequence[int] = (),
    seed: int = 0,
    sensor: Optional[str] = None,
    intensity_max: Optional[float] = None,
    forward: Optional[str] = None,
    shard: Optional[str] = None,
    batch_size: int = 8,
    concurrency: int = 2,
) -> Dict[str, int]:
    """``perturb batch INPUT --out OUT`` on Ray, for a folder of images or point clouds.

    The selection (``ids``, ``families``, ``modality``, ``severities``, ``shard``), ``seed``,
    ``sensor``, ``intensity_max`` and ``forward`` mean what the options of ``perturb batch``
    mean (with its defaults per input kind: a KITTI ``.bin`` is read as an HDL-64E, a nuScenes
    ``.pcd.bin`` as an HDL-32E looking along +y). Writes the
    same files, manifest and ``.done`` markers; sets already done and files already written are
    skipped (resumable). The work is one row per (file, unfinished set), spread with
    ``map_batches`` over ``concurrency`` actors, ``batch_size`` rows at a time.

    Returns ``{"sets": ..., "resumed": ..., "files": ..., "written": ...}``: the sets selected,
    those already done before, the files of the dataset, and the files written by this run.
    """
    ray = _ray()
    plan = _perturb.plan_batch(
        os.fspath(input),
        os.fspath(out),
        ids=list(ids),
        families=list(families),
        modality=modality,
        severities=list(severities),
        seed=seed,
        sensor=sensor,
        intensity_max=intensity_max,
        shard=shard,
        forward=forward,
    )
    files: List[str] = plan["files"]
    todo = plan["todo"]
    written = 0
    if todo:
        rows = [
            {"file": f, "seq": k, "id": id_, "severity": sev, "dir": d}
            for id_, sev, d in todo
            for k, f in enumerate(files)
        ]
        result = ray.data.from_items(rows).map_batches(
            _WriteFiles,
            fn_constructor_kwargs=dict(
                root=plan["root"],
                first_file=files[0],
                seed=seed,
                sensor=sensor,
                intensity_max=intensity_max,
                forward=forward,
            ),
            batch_size=batch_size,
            batch_format="numpy",
            compute=_pool(concurrency),
        )
        done: Dict[str, int] = {}
        for row in result.iter_rows():
            done[row["dir"]] = done.get(row["dir"], 0) + 1
            written += bool(row["written"])
        for _, _, d in todo:
            if done.get(d) != len(files):
                raise PerturbError(f"{d}: {done.get(d, 0)} of {len(files)} files came back")
            _perturb.mark_done(d, len(files))
    return {
        "sets": len(plan["sets"]),
        "resumed": len(plan["sets"]) - len(todo),
        "files": len(files),
        "written": written,
    }
