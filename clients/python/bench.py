#!/usr/bin/env python3
"""Per-call time of perturb's camera perturbations at 800x503, beside albumentations and
imagecorruptions on the same frame, and the Python call overhead over `perturb bench`.

Run it pinned to one core, with a release build of both the package and the CLI:

    cargo build --release -p perturb-cli
    pip install ./clients/python            # maturin builds the extension in release
    taskset -c 0 python3 clients/python/bench.py --cli target/release/perturb

The frame is KITTI 000000 (../shared/data) scaled to 800x503 and written to a temporary PNG
that `perturb bench --input` reads too, so both measure the same pixels. Each figure is the
median of --reps calls after one warm-up call. "overhead" is the package's median over the CLI's
median for the same perturbation (what Python, the argument checks and the output array cost).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import perturb

ROOT = pathlib.Path(__file__).resolve().parents[2]

# perturb ID -> (albumentations transform factory, imagecorruptions name); None where the library
# has no counterpart.
def _peers():
    try:
        import albumentations as A
    except ImportError:
        A = None
    alb = {}
    if A is not None:
        alb = {
            "C-A1": lambda: A.GaussNoise(p=1),
            "C-A4": lambda: A.ImageCompression(quality_range=(20, 20), p=1),
            "C-B1": lambda: A.Defocus(p=1),
            "C-B2": lambda: A.GlassBlur(p=1),
            "C-B3": lambda: A.MotionBlur(p=1),
            "C-B4": lambda: A.ZoomBlur(p=1),
            "C-B5": lambda: A.GaussianBlur(p=1),
            "C-C2": lambda: A.RandomSnow(p=1),
            "C-C3": lambda: A.RandomFog(p=1),
            "C-C4": lambda: A.RandomBrightnessContrast(brightness_limit=(0.3, 0.3), contrast_limit=0, p=1),
            "C-C7": lambda: A.RandomRain(p=1),
            "C-C11": lambda: A.RandomSunFlare(p=1),
            "C-D1": lambda: A.ElasticTransform(p=1),
            "C-D2": lambda: A.Downscale(p=1),
            "C-D4": lambda: A.Sharpen(p=1),
            "C-E5": lambda: A.CoarseDropout(p=1),
            "C-F3": lambda: A.CLAHE(p=1),
            "C-F5": lambda: A.ToGray(p=1),
            "C-F7": lambda: A.Posterize(p=1),
        }
    ic = {
        "C-A1": "gaussian_noise",
        "C-A2": "shot_noise",
        "C-A3": "impulse_noise",
        "C-A4": "jpeg_compression",
        "C-A5": "speckle_noise",
        "C-B1": "defocus_blur",
        "C-B2": "glass_blur",
        "C-B3": "motion_blur",
        "C-B4": "zoom_blur",
        "C-B5": "gaussian_blur",
        "C-C1": "frost",
        "C-C2": "snow",
        "C-C3": "fog",
        "C-C4": "brightness",
        "C-C6": "contrast",
        "C-D1": "elastic_transform",
        "C-D2": "pixelate",
        "C-F6": "saturate",
    }
    return alb, ic


def _median_ms(fn, reps: int) -> float:
    fn()  # warm-up (and, for perturb, the perturbation's setup for this geometry)
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times) * 1e3


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cli", default=str(ROOT / "target" / "release" / "perturb"), help="the perturb binary")
    ap.add_argument("--severity", type=int, default=3)
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--ids", nargs="*", help="only these perturbations (default: every camera one)")
    ap.add_argument("--peers", action=argparse.BooleanOptionalAction, default=True, help="time albumentations and imagecorruptions too")
    ap.add_argument("--markdown", action="store_true", help="print a markdown table")
    a = ap.parse_args()

    if hasattr(os, "sched_getaffinity") and len(os.sched_getaffinity(0)) != 1:
        print("note: not pinned to one core (run under `taskset -c 0`)", file=sys.stderr)
    from PIL import Image

    src = ROOT.parent / "shared" / "data" / "kitti" / "image_2" / "000000.png"
    if not src.exists():
        print(f"{src} is missing: the benchmark uses the recorded KITTI frame", file=sys.stderr)
        return 2
    frame = np.asarray(Image.open(src).convert("RGB").resize((800, 503), Image.BILINEAR)).copy()
    ids = a.ids or [e["id"] for e in perturb.catalogue("camera")]

    with tempfile.TemporaryDirectory() as tmp:
        png = pathlib.Path(tmp) / "frame_800x503.png"
        Image.fromarray(frame).save(png)
        cmd = [a.cli, "bench", "--modality", "camera", "--input", str(png), "--width", "800", "--height", "503",
               "--frames", str(a.reps), "--threads", "1", "--json"]
        for i in ids:
            cmd += ["--id", i]
        rust = json.loads(subprocess.run(cmd, check=True, capture_output=True).stdout)
    rust_ms = {(r["id"], r["severity"]): r["median_ms"] for r in rust}

    alb, ic = _peers() if a.peers else ({}, {})
    try:
        from imagecorruptions import corrupt
    except ImportError:
        corrupt = None
    rows = []
    failed = []

    def peer(name, fn, reps):
        # A peer that fails with the installed libraries (imagecorruptions 1.1.2 under numpy 2
        # and a recent scikit-image) is reported, not fatal.
        try:
            return _median_ms(fn, reps)
        except Exception as e:  # noqa: BLE001 - any failure of a third-party peer
            failed.append(f"{i} vs {name} ({type(e).__name__}: {e})")
            return None

    for i in ids:
        p = perturb.CameraPerturber(i, a.severity, seed=1)
        seq = iter(range(10**9))
        py = _median_ms(lambda: p(frame, next(seq)), a.reps)
        rs = rust_ms.get((p.id, a.severity))
        al = None
        if i in alb:
            t = alb[i]()
            al = peer("albumentations", lambda: t(image=frame), a.reps)
        ico = None
        if corrupt is not None and i in ic:
            reps = 3 if ic[i] in ("glass_blur", "zoom_blur", "elastic_transform", "frost") else a.reps
            ico = peer(f"imagecorruptions {ic[i]}",
                       lambda: corrupt(frame, corruption_name=ic[i], severity=a.severity), reps)
        rows.append((p.id, p.name, py, rs, al, ico))

    fmt = lambda v: "-" if v is None else f"{v:.2f}"
    head = ["id", "name", "perturb (Python) ms", "perturb bench (Rust) ms", "overhead", "albumentations ms", "imagecorruptions ms"]
    lines = []
    for id_, name, py, rs, al, ico in rows:
        over = "-" if not rs else f"{(py - rs) / rs * 100:+.1f}%"
        lines.append([id_, name, fmt(py), fmt(rs), over, fmt(al), fmt(ico)])
    if a.markdown:
        print("| " + " | ".join(head) + " |")
        print("|" + "---|" * len(head))
        for l in lines:
            print("| " + " | ".join(l) + " |")
    else:
        widths = [max(len(h), *(len(l[k]) for l in lines)) for k, h in enumerate(head)]
        print("  ".join(h.ljust(w) for h, w in zip(head, widths)))
        for l in lines:
            print("  ".join(c.ljust(w) for c, w in zip(l, widths)))
    py_total = sum(r[2] for r in rows if r[3])
    rs_total = sum(r[3] for r in rows if r[3])
    if rs_total:
        print(f"\ntotal over {sum(1 for r in rows if r[3])} perturbations: Python {py_total:.1f} ms, "
              f"Rust {rs_total:.1f} ms, overhead {(py_total - rs_total) / rs_total * 100:+.1f}%")
    for f in failed:
        print(f"peer failed: {f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
