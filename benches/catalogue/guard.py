#!/usr/bin/env python3
"""Per-commit guard of the camera catalogue's speed at 1920x1208 on one core (issue 35).

Runs the release `perturb bench --modality camera --format json` pinned to one core (`taskset -c
0`) --runs times, keeps for each id x severity the fastest median over the runs (this VM's host
adds bursts of load; the fastest run is the one closest to the code's own cost), and prints a
markdown table with each figure beside the previous one, from the committed baseline
benches/catalogue/camera-WxH.json:

    cargo build --release -p perturb-cli
    python3 benches/catalogue/guard.py                          # print the table, exit status
    python3 benches/catalogue/guard.py --write-docs --update-baseline   # and record it
    python3 benches/catalogue/guard.py --runs 1 --id C-B4 --id C-F2     # a quick look

Each cell reads "now (previous)", in ms (median of --frames frames). Per id, "now/prev" is the
median over severities now divided by the same median before. The "check" column flags a
severity whose median is over --budget-ms ("over") and a ratio above --slower ("slower?": a hint
only, this VM's speed drifts from day to day; compare builds back to back before calling it a
regression). The table is preceded by the date, the commit, the command and the load average
(1 min) before, during (highest sampled) and after the runs; the bench itself adds about 1.

Exit status: 0 when every id x severity except the --exempt ids (default C-F2: its 2-D FFT of a
column of 1208 = 8 x 151 rows, see docs/performance.md) has its fastest median within the budget;
1 when one does not (named on stderr); 2 on a usage or run error. A ratio flag never fails.

--write-docs replaces the text between `<!-- guard:camera-WxH begin -->` and `<!-- guard:camera-WxH
end -->` in docs/performance.md; --update-baseline replaces the baseline with this run's figures,
so the next commit compares against this one. Both need a run of the whole catalogue (no --id).
Paths (--bin, the baseline, the docs) are relative to the workspace, where the bench also runs
(its default frame is ../shared/data's KITTI 000000).

Baseline format (JSON): {"format": "perturb-guard-baseline/1", "width", "height", "commit" (short
hash the figures were measured on; "uncommitted": true when the work tree had changes), "date"
(UTC), "how" (how they were measured), "rows": [{"id", "name", "median_ms": [s1, s2, ...]}]}, one
row per line. The first baseline was parsed from the table in docs/performance.md at a commit:
`guard.py --seed-from-docs COMMIT --note "how they were measured"`.

Python 3.11 standard library only.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import statistics
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = "docs/performance.md"
FORMAT = "perturb-guard-baseline/1"


class GuardError(Exception):
    """A bad input (baseline, docs, bench output) or a failed run: message names what and where."""


# --- parsing -------------------------------------------------------------------------------------

NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def parse_docs_table(markdown: str, width: int, height: int, source: str = DOCS) -> list[dict]:
    """The rows of the first table of the section `## Camera, WxH ...` of a markdown text.

    Needs the columns `id`, `name` and `s1`, `s2`, ...; a severity cell's first number is its
    figure (so both the hand-made "5.91" and the guard's "5.91 (5.80)" read as 5.91), "-" is none.
    Returns [{"id", "name", "median_ms": [s1, s2, ...]}] in table order.
    """
    lines = markdown.splitlines()
    heading = f"## Camera, {width}x{height}"
    start = next((i for i, l in enumerate(lines) if l.startswith(heading)), None)
    if start is None:
        raise GuardError(f"{source}: no section starting with {heading!r}")
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
    first = next((i for i in range(start + 1, end) if lines[i].lstrip().startswith("|")), None)
    if first is None:
        raise GuardError(f"{source}: no table in the section {heading!r} (line {start + 1})")
    header = [c.lower() for c in _cells(lines[first])]
    sev_cols = {int(m.group(1)): j for j, c in enumerate(header) if (m := re.fullmatch(r"s(\d+)", c))}
    for need in ("id", "name"):
        if need not in header:
            raise GuardError(f"{source}:{first + 1}: the table has no {need!r} column")
    if not sev_cols or sorted(sev_cols) != list(range(1, len(sev_cols) + 1)):
        raise GuardError(f"{source}:{first + 1}: the table needs columns s1, s2, ... (has {header})")
    rows = []
    for i in range(first + 1, end):
        line = lines[i]
        if not line.lstrip().startswith("|"):
            break
        cells = _cells(line)
        if all(set(c) <= set("-: ") for c in cells):
            continue  # the separator row
        if len(cells) != len(header):
            raise GuardError(f"{source}:{i + 1}: {len(cells)} cells, the header has {len(header)}")
        medians = []
        for s in sorted(sev_cols):
            cell = cells[sev_cols[s]]
            m = NUMBER.match(cell)
            if m:
                medians.append(float(m.group()))
            elif cell in ("-", ""):
                medians.append(None)
            else:
                raise GuardError(f"{source}:{i + 1}: s{s} cell {cell!r} is not a figure in ms")
        rows.append({"id": cells[header.index("id")], "name": cells[header.index("name")], "median_ms": medians})
    if not rows:
        raise GuardError(f"{source}:{first + 1}: the table has no rows")
    return rows


def parse_bench_json(text: str, what: str = "perturb bench") -> list[dict]:
    """`perturb bench --format json`'s rows (id, name, severity, median_ms, ...), checked."""
    try:
        rows = json.loads(text)
    except json.JSONDecodeError as e:
        raise GuardError(f"{what}: output is not JSON ({e})") from None
    if not isinstance(rows, list) or not rows:
        raise GuardError(f"{what}: expected a non-empty JSON array of rows")
    for n, r in enumerate(rows):
        for key, kind in (("id", str), ("name", str), ("severity", int), ("median_ms", (int, float))):
            if not isinstance(r.get(key), kind):
                raise GuardError(f"{what}: row {n} has no {kind} field {key!r}: {r}")
    return rows


def fastest(runs: list[list[dict]]) -> list[dict]:
    """Per id x severity, the least median over the runs; ids in first-seen order.

    Returns [{"id", "name", "median_ms": [s1, s2, ...]}] (None where a severity was not run).
    """
    best: dict[str, dict] = {}
    for rows in runs:
        for r in rows:
            e = best.setdefault(r["id"], {"id": r["id"], "name": r["name"], "by_sev": {}})
            s, ms = r["severity"], float(r["median_ms"])
            e["by_sev"][s] = min(ms, e["by_sev"].get(s, ms))
    out = []
    for e in best.values():
        n = max(e["by_sev"])
        out.append({"id": e["id"], "name": e["name"], "median_ms": [e["by_sev"].get(s) for s in range(1, n + 1)]})
    return out


# --- the baseline --------------------------------------------------------------------------------


def load_baseline(path: Path) -> dict:
    """The baseline file, checked (see the module's docstring for its format)."""
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise GuardError(f"{path}: no baseline (create one with --update-baseline or --seed-from-docs)") from None
    except json.JSONDecodeError as e:
        raise GuardError(f"{path}: not JSON ({e})") from None
    if data.get("format") != FORMAT:
        raise GuardError(f"{path}: format is {data.get('format')!r}, expected {FORMAT!r}")
    for key in ("commit", "date", "how", "rows"):
        if key not in data:
            raise GuardError(f"{path}: no {key!r} field")
    for n, r in enumerate(data["rows"]):
        ms = r.get("median_ms")
        if not isinstance(r.get("id"), str) or not isinstance(ms, list):
            raise GuardError(f"{path}: row {n} needs an id and a median_ms list: {r}")
        if any(v is not None and not isinstance(v, (int, float)) for v in ms):
            raise GuardError(f"{path}: row {n} ({r['id']}): median_ms holds a non-number: {ms}")
    return data


def write_baseline(path: Path, a: argparse.Namespace, commit: str, uncommitted: bool, date: str, how: str, rows):
    """Writes the baseline file (see the module's docstring) with figures rounded to 1 us."""
    rows = [{**r, "median_ms": [None if v is None else round(v, 3) for v in r["median_ms"]]} for r in rows]
    head = {"format": FORMAT, "width": a.width, "height": a.height, "commit": commit}
    head |= {"uncommitted": uncommitted, "date": date, "how": how}
    path.write_text(dump_baseline(head | {"rows": rows}))
    print(f"guard: wrote {rel(path)} ({len(rows)} ids from {commit})", file=sys.stderr)


def dump_baseline(data: dict) -> str:
    """The baseline as JSON text with one row per line (readable diffs from commit to commit)."""
    head = {k: v for k, v in data.items() if k != "rows"}
    text = json.dumps(head, indent=2)[:-2]  # without the closing "\n}"
    rows = ",\n".join("    " + json.dumps(r) for r in data["rows"])
    return f'{text},\n  "rows": [\n{rows}\n  ]\n}}\n'


# --- comparison ----------------------------------------------------------------------------------


@dataclass
class Line:
    """One id of the table: its figures now and before, and what the guard makes of them."""

    id: str
    name: str
    now: list[float | None]
    prev: list[float | None] | None
    ratio: float | None
    over: list[int]  # severities whose median is over the budget
    exempt: bool
    slower: bool


def compare(now: list[dict], prev: list[dict] | None, budget_ms: float, slower: float, exempt: list[str]) -> list[Line]:
    """Lines of the table: per id, the severities over `budget_ms`, and the ratio of the median
    over severities now to the median over the same severities before (flagged above `slower`)."""
    before = {r["id"]: r["median_ms"] for r in prev or []}
    exempt_ids = {e.upper() for e in exempt}
    out = []
    for r in now:
        p = before.get(r["id"])
        ratio = None
        if p is not None:
            pairs = [(a, b) for a, b in zip(r["median_ms"], p) if a is not None and b is not None]
            if pairs and statistics.median(b for _, b in pairs) > 0:
                ratio = statistics.median(a for a, _ in pairs) / statistics.median(b for _, b in pairs)
        over = [s for s, v in enumerate(r["median_ms"], 1) if v is not None and v > budget_ms]
        out.append(
            Line(
                id=r["id"],
                name=r["name"],
                now=r["median_ms"],
                prev=p,
                ratio=ratio,
                over=over,
                exempt=r["id"].upper() in exempt_ids,
                slower=ratio is not None and ratio > slower,
            )
        )
    return out


def failures(lines: list[Line]) -> list[Line]:
    """The lines that fail the guard: over the budget at some severity and not exempt."""
    return [l for l in lines if l.over and not l.exempt]


def exit_status(lines: list[Line]) -> int:
    """1 when a non-exempt id is over the budget at some severity, else 0 (ratios never fail)."""
    return 1 if failures(lines) else 0


def severities(sevs: list[int]) -> str:
    """[1, 2, 3, 5] -> "s1-s3, s5"."""
    parts, i = [], 0
    while i < len(sevs):
        j = i
        while j + 1 < len(sevs) and sevs[j + 1] == sevs[j] + 1:
            j += 1
        parts.append(f"s{sevs[i]}" if i == j else f"s{sevs[i]}-s{sevs[j]}")
        i = j + 1
    return ", ".join(parts)


def check_text(line: Line, budget_ms: float) -> str:
    """The table's last column for one id."""
    flags = []
    if line.over:
        flags.append(f"over {budget_ms:g} ms at {severities(line.over)}" + (" (exempt)" if line.exempt else ""))
    if line.slower:
        flags.append("slower?")
    if line.prev is None:
        flags.append("new")
    return "; ".join(flags) or "ok"


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def render_table(lines: list[Line], budget_ms: float, slower: float) -> str:
    """The markdown table and a summary line under it."""
    n = max(len(l.now) for l in lines)
    out = [
        "| id | name | " + " | ".join(f"s{s}" for s in range(1, n + 1)) + " | now/prev | check |",
        "|---|---|" + "---:|" * n + "---:|---|",
    ]
    for l in lines:
        cells = []
        for s in range(n):
            now = l.now[s] if s < len(l.now) else None
            if l.prev is None:
                cells.append(_ms(now))
            else:
                cells.append(f"{_ms(now)} ({_ms(l.prev[s] if s < len(l.prev) else None)})")
        ratio = "-" if l.ratio is None else f"{l.ratio:.2f}"
        out.append(f"| {l.id} | {l.name} | " + " | ".join(cells) + f" | {ratio} | {check_text(l, budget_ms)} |")
    within = sum(1 for l in lines if not l.over)
    rows = sorted(v for l in lines for v in l.now if v is not None)
    summary = (
        f"\n{within}/{len(lines)} ids within {budget_ms:g} ms at every severity;"
        f" median over all {len(rows)} rows {statistics.median(rows):.2f} ms."
    )
    over = [f"{l.id} {severities(l.over)}" + (" (exempt)" if l.exempt else "") for l in lines if l.over]
    if over:
        summary += " Over: " + ", ".join(over) + "."
    slow = [l.id for l in lines if l.slower]
    if slow:
        summary += f" Slower? (now/prev above {slower:g}, a hint: this VM drifts): " + ", ".join(slow) + "."
    summary += " Guard: " + ("FAIL" if failures(lines) else "pass") + "."
    return "\n".join(out) + "\n" + summary + "\n"


def replace_between_markers(text: str, key: str, body: str, source: str = DOCS) -> str:
    """`text` with what lies between `<!-- guard:KEY begin -->` and `<!-- guard:KEY end -->`
    replaced by `body` (the markers stay, everything outside them is unchanged)."""
    begin, end = f"<!-- guard:{key} begin -->", f"<!-- guard:{key} end -->"
    if text.count(begin) != 1 or text.count(end) != 1:
        found = f"found {text.count(begin)} and {text.count(end)}"
        raise GuardError(f"{source}: needs exactly one {begin!r} and one {end!r} ({found})")
    i, j = text.index(begin) + len(begin), text.index(end)
    if j < i:
        raise GuardError(f"{source}: {end!r} comes before {begin!r}")
    return text[:i] + "\n" + body.strip("\n") + "\n" + text[j:]


# --- running -------------------------------------------------------------------------------------


def rel(path: Path) -> str:
    """`path` relative to the workspace when it lies inside it."""
    path = path.resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def git(*args: str) -> str:
    p = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True)
    if p.returncode != 0:
        raise GuardError(f"git {' '.join(args)}: {p.stderr.strip()}")
    return p.stdout.strip()


class LoadSampler:
    """The 1-minute load average, sampled every few seconds in a thread; keeps the highest."""

    def __init__(self, every_s: float = 5.0):
        self.highest = os.getloadavg()[0]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(every_s,), daemon=True)

    def _run(self, every_s: float):
        while not self._stop.wait(every_s):
            self.highest = max(self.highest, os.getloadavg()[0])

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.highest = max(self.highest, os.getloadavg()[0])


def bench_command(a: argparse.Namespace) -> list[str]:
    cmd = ["taskset", "-c", "0", str(Path(a.bin) / "perturb"), "bench", "--modality", "camera", "--format", "json"]
    cmd += ["--width", str(a.width), "--height", str(a.height), "--frames", str(a.frames)]
    for i in a.id:
        cmd += ["--id", i]
    return cmd


def run_bench(cmd: list[str], n: int, runs: int) -> list[dict]:
    print(f"guard: run {n}/{runs}: {shlex.join(cmd)}", file=sys.stderr, flush=True)
    t = time.monotonic()
    p = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)  # stderr: the bench's own lines
    if p.returncode != 0:
        raise GuardError(f"run {n}: {shlex.join(cmd)} exited with status {p.returncode}")
    rows = parse_bench_json(p.stdout, f"run {n}")
    print(f"guard: run {n}/{runs}: {len(rows)} rows in {time.monotonic() - t:.0f} s", file=sys.stderr, flush=True)
    return rows


def seed(a: argparse.Namespace, path: Path) -> int:
    """--seed-from-docs: the baseline from the table in docs/performance.md at a commit."""
    commit = git("rev-parse", "--short", a.seed_from_docs)
    rows = parse_docs_table(git("show", f"{commit}:{DOCS}"), a.width, a.height, f"{commit}:{DOCS}")
    date = git("show", "-s", "--format=%cs", commit)
    write_baseline(path, a, commit, False, date, a.note or f"parsed from the table in {DOCS} at {commit}", rows)
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3, help="bench runs; the fastest median per cell is kept (default 3)")
    ap.add_argument("--bin", default="target/release", help="the perturb binary's folder (default target/release)")
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1208)
    ap.add_argument("--frames", type=int, default=10, help="frames timed per id x severity (default 10)")
    ap.add_argument("--id", action="append", default=[], help="only this id (repeatable; a quick look)")
    ap.add_argument("--budget-ms", type=float, default=33.0, help="per-frame budget (default 33)")
    ap.add_argument("--slower", type=float, default=1.25, help="flag now/previous above this ratio (default 1.25)")
    ap.add_argument("--exempt", action="append", help="ids allowed over the budget (repeatable; default C-F2)")
    ap.add_argument("--baseline", type=Path, help="previous figures (default benches/catalogue/camera-WxH.json)")
    ap.add_argument("--write-docs", action="store_true", help=f"write the table into {DOCS} between its guard markers")
    ap.add_argument("--update-baseline", action="store_true", help="replace the baseline with this run's figures")
    ap.add_argument("--seed-from-docs", metavar="COMMIT", help=f"only write the baseline from {DOCS}'s table at COMMIT")
    ap.add_argument("--note", help="with --seed-from-docs: how the table's figures were measured")
    a = ap.parse_args(argv)
    exempt = a.exempt if a.exempt is not None else ["C-F2"]
    key = f"camera-{a.width}x{a.height}"
    path = ROOT / (a.baseline or Path("benches") / "catalogue" / f"{key}.json")
    if a.runs < 1 or a.frames < 1:
        ap.error("--runs and --frames must be at least 1")
    if a.id and (a.write_docs or a.update_baseline):
        ap.error("--write-docs and --update-baseline need the whole catalogue (no --id)")
    try:
        if a.seed_from_docs:
            return seed(a, path)
        if not (Path(a.bin) if Path(a.bin).is_absolute() else ROOT / a.bin).joinpath("perturb").is_file():
            raise GuardError(f"{a.bin}/perturb is missing: cargo build --release -p perturb-cli")
        prev = load_baseline(path) if path.exists() else None
        if prev and (prev.get("width"), prev.get("height")) != (a.width, a.height):
            size = f"{prev.get('width')}x{prev.get('height')}"
            raise GuardError(f"{path}: figures for {size}, this run is {a.width}x{a.height}")
        commit = git("rev-parse", "--short", "HEAD")
        dirty = bool(git("status", "--porcelain", "--untracked-files=no"))
        cmd = bench_command(a)
        started = time.gmtime()
        load_before = os.getloadavg()[0]
        with LoadSampler() as load:
            runs = [run_bench(cmd, n, a.runs) for n in range(1, a.runs + 1)]
        load_after = os.getloadavg()[0]
        now = fastest(runs)
        lines = compare(now, prev["rows"] if prev else None, a.budget_ms, a.slower, exempt)
        nice = os.nice(0)
        shown = ("nice -n %d " % nice if nice else "") + shlex.join(cmd)
        if prev:
            changes = " (with uncommitted changes)" if prev.get("uncommitted") else ""
            before = f"commit `{prev['commit']}`{changes}, {prev['date']}: {prev['how']}"
        else:
            before = f"none ({rel(path)} does not exist)"
        head = (
            f"Guard run {time.strftime('%Y-%m-%d %H:%M UTC', started)} on commit `{commit}`"
            f"{' (with uncommitted changes)' if dirty else ''}: `{shown}`, {a.runs} run(s), fastest median per cell"
            f" (ms, median of {a.frames} frames). Load average (1 min) {load_before:.2f} before, at most"
            f" {load.highest:.2f} during, {load_after:.2f} after (the bench itself adds about 1)."
            f" In parentheses, the previous figures: {before}."
        )
        report = head + "\n\n" + render_table(lines, a.budget_ms, a.slower)
        print(report)
        if a.write_docs:
            docs = ROOT / DOCS
            docs.write_text(replace_between_markers(docs.read_text(), key, report))
            print(f"guard: wrote the table into {DOCS}", file=sys.stderr)
        if a.update_baseline:
            how = (
                f"benches/catalogue/guard.py: `{shown}`, fastest median of {a.runs} run(s);"
                f" load average (1 min) {load_before:.2f} before, at most {load.highest:.2f} during"
            )
            write_baseline(path, a, commit, dirty, time.strftime("%Y-%m-%d", started), how, now)
        for l in failures(lines):
            print(f"guard: {l.id} ({l.name}) over {a.budget_ms:g} ms at {severities(l.over)}", file=sys.stderr)
        return exit_status(lines)
    except GuardError as e:
        print(f"guard: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
