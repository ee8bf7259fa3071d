#!/usr/bin/env python3
"""Side-by-side speed of this project's camera perturbations and their peers, on one core.

Ours is timed through the CLI bench (`perturb bench --modality camera --json --id ID`, the median
of --frames frames after a warm-up frame, on a one-thread pool); the peers (albumentations,
imagecorruptions, OpenCV's own JPEG round trip) are timed in this process on the same frame, the
median of --repeat calls after a warm-up call. Both run on the same CPU (this process pins itself,
and its children inherit it) and alternate pair by pair, so a slow stretch of the machine hits both
sides of a pair. The frame is the KITTI frame from ../shared/data scaled to each size with OpenCV
(INTER_AREA) and written once as a PNG that both sides read, so both work on the same pixels.

Each pair is timed at severities 1..5: ours at the severity, the peer with parameters matched to
that severity where the peer has a comparable parameter (pixelate factor, JPEG quality, blur
radius, ...), with fixed parameters otherwise. The table shows ours and the peer (median over the
severities, ms per call), their ratio ours/peer (median of the per-severity ratios; below 1: ours is
faster) and the worst severity's ratio. A "frame copy" row times np.copyto of the frame (the memory
limit per-pixel operations aim at) and the per-pixel rows show ours / copy.

    cargo build --release -p perturb-cli
    python3 benches/compare/compare.py                       # both sizes, every pair
    python3 benches/compare/compare.py --sizes 800x503 --peers albumentations --ids C-F5 C-A4
    python3 benches/compare/compare.py --format markdown     # the table in docs/performance.md

Needs numpy and opencv-python; `pip install albumentations imagecorruptions` for those peers
(a peer that is not installed is skipped with a note).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
DEFAULT_FRAME = ROOT.parent / "shared" / "data" / "kitti" / "image_2" / "000000.png"

# Our parameters per severity (perturb-core's constants), used to match the peers' parameters.
BRIGHTNESS_UP = [1.1, 1.2, 1.3, 1.5, 1.7]
BRIGHTNESS_DOWN = [0.9, 0.8, 0.7, 0.5, 0.3]
CONTRAST = [1.1, 1.2, 1.3, 1.5, 1.7]
POSTERIZE_BITS = [7, 6, 5, 3, 2]  # 128, 64, 32, 8, 4 levels
SATURATION_UP = [1.05, 1.15, 1.40, 1.65, 1.90]
SATURATION_DOWN = [0.90, 0.85, 0.60, 0.35, 0.10]
JPEG_QUALITY = [30, 18, 15, 10, 5]
PIXELATE = [0.85, 0.55, 0.35, 0.20, 0.10]
SNOW_WEIGHT = [0.15, 0.22, 0.30, 0.45, 0.60]
SHARPEN_W = [0.9, 0.8, 0.7, 0.6, 0.5]
GAUSSIAN_KERNEL = [3, 7, 15, 25, 41]
DEFOCUS_RADIUS = [2, 5, 6, 9, 12]
MOTION_RADIUS = [2, 4, 6, 10, 15]
GAUSSIAN_SIGMA = [0.03, 0.06, 0.12, 0.18, 0.22]
IMPULSE_AMOUNT = [0.01, 0.02, 0.04, 0.065, 0.10]
SPECKLE_SIGMA = [0.02, 0.05, 0.09, 0.14, 0.20]
CLAHE_CLIP = [1.0, 3.0, 5.0, 7.0, 10.0]
FOG_WEIGHT = [0.05, 0.12, 0.22, 0.35, 0.60]
CUTOUT_COUNT = [1, 2, 4, 6, 10]

# Operations whose output depends on each pixel alone: their target is "within 2x of a frame copy".
PER_PIXEL = {"C-C4", "C-C5", "C-C6", "C-F1", "C-F4", "C-F5", "C-F6", "C-F7", "C-F8"}


@dataclass
class Pair:
    """One of our perturbations and a peer's operation of the same kind."""

    ours: str
    peer: str  # "albumentations", "imagecorruptions" or "opencv"
    label: str
    # severity (1..5) -> a function of the image; built once per severity, outside the timing.
    make: Callable[[int], Callable[[np.ndarray], np.ndarray]]
    note: str = ""


def albumentations_pairs() -> list[Pair]:
    import albumentations as A

    def t(transform) -> Callable[[np.ndarray], np.ndarray]:
        return lambda img: transform(image=img)["image"]

    def rbc(b=0.0, c=0.0):
        return A.RandomBrightnessContrast(brightness_limit=(b, b), contrast_limit=(c, c), p=1)

    def hsv(shift):
        return A.HueSaturationValue(
            hue_shift_limit=(0, 0), sat_shift_limit=(shift, shift), val_shift_limit=(0, 0), p=1
        )

    area_nearest = {"downscale": cv2.INTER_AREA, "upscale": cv2.INTER_NEAREST}
    pairs = [
        ("C-C4", "RandomBrightnessContrast (brightness f-1)", lambda s: t(rbc(b=BRIGHTNESS_UP[s] - 1))),
        ("C-C5", "RandomBrightnessContrast (brightness f-1)", lambda s: t(rbc(b=BRIGHTNESS_DOWN[s] - 1))),
        ("C-C6", "RandomBrightnessContrast (contrast f-1)", lambda s: t(rbc(c=CONTRAST[s] - 1))),
        ("C-F5", "ToGray", lambda s: t(A.ToGray(p=1))),
        ("C-F7", "Posterize (bits matched)", lambda s: t(A.Posterize(num_bits=POSTERIZE_BITS[s], p=1))),
        ("C-F6", "HueSaturationValue (saturation)", lambda s: t(hsv(round((SATURATION_UP[s] - 1) * 100)))),
        ("C-F8", "HueSaturationValue (saturation)", lambda s: t(hsv(round((SATURATION_DOWN[s] - 1) * 100)))),
        ("C-F4", "PlanckianJitter (per-channel gains)", lambda s: t(A.PlanckianJitter(p=1))),
        ("C-F1", "ChannelShuffle", lambda s: t(A.ChannelShuffle(p=1))),
        ("C-A4", "ImageCompression (quality matched)",
         lambda s: t(A.ImageCompression(quality_range=(JPEG_QUALITY[s], JPEG_QUALITY[s]), p=1))),
        ("C-D2", "Downscale (area down, nearest up)",
         lambda s: t(A.Downscale(scale_range=(PIXELATE[s], PIXELATE[s]), interpolation_pair=area_nearest, p=1))),
        ("C-C2", "RandomSnow (bleach)",
         lambda s: t(A.RandomSnow(snow_point_range=(SNOW_WEIGHT[s], SNOW_WEIGHT[s]), p=1))),
        ("C-D4", "Sharpen (kernel)",
         lambda s: t(A.Sharpen(alpha=(1 - SHARPEN_W[s], 1 - SHARPEN_W[s]), lightness=(1, 1), p=1))),
        ("C-A1", "GaussNoise", lambda s: t(A.GaussNoise(std_range=(GAUSSIAN_SIGMA[s],) * 2, p=1))),
        ("C-A2", "ShotNoise", lambda s: t(A.ShotNoise(p=1))),
        ("C-A3", "SaltAndPepper", lambda s: t(A.SaltAndPepper(amount=(IMPULSE_AMOUNT[s],) * 2, p=1))),
        ("C-A5", "MultiplicativeNoise (per element)",
         lambda s: t(A.MultiplicativeNoise(multiplier=(1 - SPECKLE_SIGMA[s], 1 + SPECKLE_SIGMA[s]),
                                           per_channel=True, elementwise=True, p=1))),
        ("C-B1", "Defocus (radius matched)", lambda s: t(A.Defocus(radius=(DEFOCUS_RADIUS[s],) * 2, p=1))),
        ("C-B2", "GlassBlur", lambda s: t(A.GlassBlur(p=1))),
        ("C-B3", "MotionBlur (kernel matched)",
         lambda s: t(A.MotionBlur(blur_limit=(2 * MOTION_RADIUS[s] + 1,) * 2, p=1))),
        ("C-B4", "ZoomBlur", lambda s: t(A.ZoomBlur(p=1))),
        ("C-B5", "GaussianBlur (kernel matched)",
         lambda s: t(A.GaussianBlur(blur_limit=(GAUSSIAN_KERNEL[s],) * 2, sigma_limit=(0, 0), p=1))),
        ("C-C3", "RandomFog", lambda s: t(A.RandomFog(fog_coef_range=(FOG_WEIGHT[s],) * 2, p=1))),
        ("C-C7", "RandomRain", lambda s: t(A.RandomRain(p=1))),
        ("C-C11", "RandomSunFlare", lambda s: t(A.RandomSunFlare(p=1))),
        ("C-D1", "ElasticTransform", lambda s: t(A.ElasticTransform(p=1))),
        ("C-E1", "Spatter (mud)", lambda s: t(A.Spatter(mode="mud", p=1))),
        ("C-E5", "CoarseDropout (holes matched)",
         lambda s: t(A.CoarseDropout(num_holes_range=(CUTOUT_COUNT[s],) * 2, p=1))),
        ("C-F3", "CLAHE (clip matched)", lambda s: t(A.CLAHE(clip_limit=(CLAHE_CLIP[s],) * 2, p=1))),
    ]
    return [Pair(o, "albumentations", label, make) for o, label, make in pairs]


def opencv_pairs() -> list[Pair]:
    def jpeg(s: int) -> Callable[[np.ndarray], np.ndarray]:
        q = [int(cv2.IMWRITE_JPEG_QUALITY), JPEG_QUALITY[s]]

        def run(img: np.ndarray) -> np.ndarray:
            ok, buf = cv2.imencode(".jpg", img, q)
            return cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)

        return run

    return [Pair("C-A4", "opencv", "imencode + imdecode (libjpeg-turbo)", jpeg)]


def imagecorruptions_pairs() -> list[Pair]:
    from imagecorruptions import corrupt

    names = {
        "C-A1": "gaussian_noise", "C-A2": "shot_noise", "C-A3": "impulse_noise",
        "C-A5": "speckle_noise", "C-A4": "jpeg_compression", "C-B1": "defocus_blur",
        "C-B2": "glass_blur", "C-B3": "motion_blur", "C-B4": "zoom_blur", "C-B5": "gaussian_blur",
        "C-C1": "frost", "C-C2": "snow", "C-C3": "fog", "C-C4": "brightness", "C-C6": "contrast",
        "C-D1": "elastic_transform", "C-D2": "pixelate", "C-E1": "spatter", "C-F6": "saturate",
    }

    def make(name: str) -> Callable[[int], Callable[[np.ndarray], np.ndarray]]:
        return lambda s: (lambda img: corrupt(img, corruption_name=name, severity=s + 1))

    return [Pair(o, "imagecorruptions", n, make(n)) for o, n in names.items()]


PEERS = {
    "albumentations": albumentations_pairs,
    "opencv": opencv_pairs,
    "imagecorruptions": imagecorruptions_pairs,
}


def time_peer(fn: Callable[[np.ndarray], np.ndarray], img: np.ndarray, repeat: int, budget_s: float) -> float:
    """Median ms per call over up to `repeat` calls (fewer when a call is slow), after a warm-up."""
    t0 = time.perf_counter()
    fn(img)
    first = time.perf_counter() - t0
    n = max(1, min(repeat, int(budget_s / max(first, 1e-6))))
    samples = []
    for _ in range(n):
        t0 = time.perf_counter_ns()
        fn(img)
        samples.append((time.perf_counter_ns() - t0) / 1e6)
    return statistics.median(samples)


def time_copy(img: np.ndarray, repeat: int = 200) -> float:
    """Median ms of copying the frame into a preallocated frame (read + write of every byte)."""
    dst = np.empty_like(img)
    np.copyto(dst, img)
    samples = []
    for _ in range(repeat):
        t0 = time.perf_counter_ns()
        np.copyto(dst, img)
        samples.append((time.perf_counter_ns() - t0) / 1e6)
    return statistics.median(samples)


def time_ours(perturb: Path, frame: Path, w: int, h: int, ident: str, frames: int) -> dict[int, float]:
    """Our median ms per severity, from the CLI bench."""
    out = subprocess.run(
        [str(perturb), "bench", "--modality", "camera", "--input", str(frame), "--width", str(w),
         "--height", str(h), "--id", ident, "--frames", str(frames), "--json"],
        check=True, capture_output=True, text=True,
    )
    return {row["severity"]: row["median_ms"] for row in json.loads(out.stdout)}


@dataclass
class Result:
    pair: Pair
    ours: dict[int, float] = field(default_factory=dict)
    peer: dict[int, float] = field(default_factory=dict)
    failed: str = ""  # why the peer could not run (then the pair has no ratios)

    def ratios(self) -> dict[int, float]:
        if self.failed:
            return {}
        return {s: self.ours[s] / self.peer[s] for s in self.ours if s in self.peer and self.peer[s] > 0}


def parse_size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", nargs="+", default=["800x503", "1920x1208"], help="WxH, each")
    ap.add_argument("--peers", nargs="+", default=list(PEERS), choices=list(PEERS))
    ap.add_argument("--ids", nargs="*", default=[], help="only these of our IDs")
    ap.add_argument("--severities", nargs="+", type=int, default=[1, 2, 3, 4, 5])
    ap.add_argument("--frames", type=int, default=30, help="frames per severity for ours")
    ap.add_argument("--repeat", type=int, default=30, help="calls per severity for a peer")
    ap.add_argument("--budget", type=float, default=1.0,
                    help="seconds of timed calls per peer and severity at most (slow peers get fewer calls)")
    ap.add_argument("--rounds", type=int, default=1, help="whole passes; each cell keeps its fastest")
    ap.add_argument("--cpu", type=int, default=0, help="the one CPU everything runs on (-1: do not pin)")
    ap.add_argument("--perturb", type=Path, default=ROOT / "target" / "release" / "perturb")
    ap.add_argument("--frame", type=Path, default=DEFAULT_FRAME)
    ap.add_argument("--format", choices=["table", "markdown", "json"], default="table")
    a = ap.parse_args()

    if a.cpu >= 0:
        os.sched_setaffinity(0, {a.cpu})
    cv2.setNumThreads(1)
    if not a.perturb.exists():
        sys.exit(f"{a.perturb} does not exist: build it with `cargo build --release -p perturb-cli`")
    if not a.frame.exists():
        sys.exit(f"the frame {a.frame} does not exist (give --frame)")
    pairs: list[Pair] = []
    versions = {"opencv": cv2.__version__, "numpy": np.__version__}
    for name in a.peers:
        try:
            pairs += PEERS[name]()
            if name != "opencv":
                versions[name] = importlib.metadata.version(name)
        except ImportError as e:
            print(f"note: {name} is not installed ({e}); its pairs are skipped", file=sys.stderr)
    if a.ids:
        wanted = {i.upper() for i in a.ids}
        pairs = [p for p in pairs if p.ours.upper() in wanted]
    if not pairs:
        sys.exit("no pair selected")
    sevs = [s for s in a.severities if 1 <= s <= 5]

    bgr = cv2.imread(str(a.frame), cv2.IMREAD_COLOR)
    report: dict[str, object] = {
        "cpu": a.cpu, "versions": versions, "frame": str(a.frame), "sizes": {},
    }
    with tempfile.TemporaryDirectory(prefix="perturb-compare-") as tmp:
        for size in a.sizes:
            w, h = parse_size(size)
            scaled = cv2.resize(bgr, (w, h), interpolation=cv2.INTER_AREA)
            png = Path(tmp) / f"frame_{w}x{h}.png"
            cv2.imwrite(str(png), scaled)
            rgb = np.ascontiguousarray(cv2.cvtColor(scaled, cv2.COLOR_BGR2RGB))
            copy_ms = min(time_copy(rgb) for _ in range(a.rounds))
            results = [Result(p) for p in pairs]
            ours_cache: dict[str, dict[int, float]] = {}
            for rnd in range(a.rounds):
                for r in results:
                    print(f"{size} round {rnd + 1}: {r.pair.ours} vs {r.pair.peer} {r.pair.label}", file=sys.stderr)
                    # Ours once per ID and round (several peers share an ID), right before its peers.
                    key = r.pair.ours
                    if key not in ours_cache:
                        ours_cache[key] = time_ours(a.perturb, png, w, h, key, a.frames)
                    for s, ms in ours_cache[key].items():
                        if s in sevs:
                            r.ours[s] = min(r.ours.get(s, math.inf), ms)
                    for s in sevs:
                        try:
                            fn = r.pair.make(s - 1)
                            ms = time_peer(fn, rgb, a.repeat, a.budget)
                        except Exception as e:  # a peer broken by its own dependencies
                            r.failed = f"{type(e).__name__}: {e}"
                            print(f"note: {r.pair.peer} {r.pair.label} failed ({r.failed}); pair skipped",
                                  file=sys.stderr)
                            break
                        r.peer[s] = min(r.peer.get(s, math.inf), ms)
                ours_cache.clear()
            report["sizes"][size] = {"copy_ms": copy_ms, "rows": results}
    print_report(report, a.format)
    return 0


def summary(r: Result) -> tuple[float, float, float, int, float]:
    ratios = r.ratios()
    worst = max(ratios, key=ratios.get)
    return (
        statistics.median(r.ours.values()),
        statistics.median(r.peer.values()),
        statistics.median(ratios.values()),
        worst,
        ratios[worst],
    )


def print_report(report: dict, fmt: str) -> None:
    if fmt == "json":
        out = {k: v for k, v in report.items() if k != "sizes"}
        out["sizes"] = {}
        for size, d in report["sizes"].items():
            out["sizes"][size] = {
                "copy_ms": d["copy_ms"],
                "rows": [
                    {"id": r.pair.ours, "peer": r.pair.peer, "op": r.pair.label,
                     "ours_ms": r.ours, "peer_ms": r.peer, "ratio": r.ratios()}
                    for r in d["rows"]
                ],
            }
        print(json.dumps(out, indent=1))
        return
    md = fmt == "markdown"
    vers = ", ".join(f"{k} {v}" for k, v in report["versions"].items())
    print(f"one core (CPU {report['cpu']}), {vers}; ms per call, median over severities; "
          f"ratio = ours / peer (median over severities; < 1: ours faster)")
    for size, d in report["sizes"].items():
        copy_ms = d["copy_ms"]
        print(f"\n{size}: frame copy (np.copyto) {copy_ms:.3f} ms\n")
        head = ["id", "peer", "peer's operation", "ours ms", "peer ms", "ours/peer", "worst (sev)", "ours/copy"]
        if md:
            print("| " + " | ".join(head) + " |")
            print("|---|---|---|---:|---:|---:|---:|---:|")
        else:
            print(f"{head[0]:<6} {head[1]:<16} {head[2]:<44} {head[3]:>8} {head[4]:>9} {head[5]:>9} {head[6]:>12} {head[7]:>9}")
        slower = []
        ratios_by_peer: dict[str, list[float]] = {}
        for r in d["rows"]:
            if not r.ratios():
                continue
            o, p, ratio, ws, wr = summary(r)
            ratios_by_peer.setdefault(r.pair.peer, []).append(ratio)
            per_copy = f"{o / copy_ms:.1f}" if r.pair.ours in PER_PIXEL else ""
            worst = f"{wr:.2f} (s{ws})"
            if wr > 1.0:
                slower.append(f"{r.pair.ours} vs {r.pair.label}")
            if md:
                print(f"| {r.pair.ours} | {r.pair.peer} | {r.pair.label} | {o:.3f} | {p:.3f} | {ratio:.2f} | {worst} | {per_copy} |")
            else:
                print(f"{r.pair.ours:<6} {r.pair.peer:<16} {r.pair.label:<44} {o:>8.3f} {p:>9.3f} {ratio:>9.2f} {worst:>12} {per_copy:>9}")
        print()
        for peer, rs in ratios_by_peer.items():
            gm = math.exp(sum(math.log(x) for x in rs) / len(rs))
            print(f"{size} {peer}: geometric mean of ours/peer over {len(rs)} pairs {gm:.3f} ({1 / gm:.1f}x faster)")
        print(f"{size}: pairs where ours is slower at some severity: {', '.join(slower) if slower else 'none'}")
        broken = [f"{r.pair.ours} vs {r.pair.peer} {r.pair.label} ({r.failed})" for r in d["rows"] if r.failed]
        if broken:
            print(f"{size}: peers that failed to run: {'; '.join(broken)}")


if __name__ == "__main__":
    sys.exit(main())
