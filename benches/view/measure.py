#!/usr/bin/env python3
"""Measures the live view's cost and the recorder's compression on loopback (the figures of
docs/performance.md, "Live view and recording compression").

  python3 benches/view/measure.py [--bin target/release] [--seconds 20] [--only view|record]

1. view: the safety bench's healthy pipeline (benches/safety/measure.py: synthetic camera
   1920x1208 at 30 Hz and VLP-32C at 10 Hz -> perturb-bridge -> perturbd (C-A1 s2, L-B1 s1) ->
   perturb-bridge -> rospy subscribers on ROS 1), without [view], with [view] and no viewer,
   with a viewer (tests/tests/view_client/client.js, the npm @foxglove/ws-protocol client) that
   only counts (a viewer on another computer) and with one that decodes everything on this one:
   the egresses' latency p50 / p99 from the bridge's report, and the frame rate the viewer got;
2. record: a synthetic camera (800x503 and 1920x1208, 30 Hz) in one bridge, `perturb-bridge
   record --raw-only` of it in another, with zstd:1, zstd:3, lz4 and none: the recorder's CPU
   (user + system, from wait4) per second of stream, and the bag's size per minute.

Needs Debian's roscore and rospy (/usr/bin/python3), node with `npm ci` done in
tests/tests/view_client, and the binaries (--bin).
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benches/safety"))
import measure as safety  # noqa: E402  (the safety bench's roscore, daemon and bridge runner)

CLIENT = ROOT / "tests/tests/view_client/client.js"


def cpu_s(pid):
    """User + system CPU seconds a running process used so far."""
    f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")


def view(r, tmp, a):
    daemon_cfg = tmp / "perturbd.toml"
    daemon_cfg.write_text('[[streams]]\nname = "cam"\nmodality = "camera"\n'
                          'perturbation = { id = "C-A1", severity = 2, seed = 1 }\n\n'
                          '[[streams]]\nname = "lid"\nmodality = "lidar"\nsensor = "vlp32c"\n'
                          'perturbation = { id = "L-B1", severity = 1, seed = 1 }\n')
    print("## egress latency (source -> ROS 1 write returned), p50 / p99 ms, without and with a viewer")
    for name in a.order.split(","):
        cfg = safety.bridge_cfg(tmp, name, "raw")
        port = safety.free_port()
        if not name.startswith("none"):
            cfg.write_text(cfg.read_text() + f"[view]\nport = {port}\n")
        d = r.daemon(daemon_cfg)
        subs = [r.sub("/ads/camera", "image", "cam"), r.sub("/ads/lidar", "cloud", "lid")]
        b = r.bridge(cfg)
        viewer = None
        if name.startswith("view") or name.startswith("light"):
            while True:
                try:
                    safety.socket.create_connection(("127.0.0.1", port), 0.2).close()
                    break
                except OSError:
                    time.sleep(0.1)
            light = ["--count-only"] if name.startswith("light") else []
            viewer = subprocess.Popen(["node", str(CLIENT), f"ws://127.0.0.1:{port}"] + light,
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
            ready = json.loads(viewer.stdout.readline())
            assert ready.get("ready"), ready
        time.sleep(a.seconds)
        bridge_cpu = cpu_s(b.pid)
        viewer_cpu = cpu_s(viewer.pid) if viewer else 0.0
        got = None
        if viewer:
            viewer.stdin.write('{"cmd": "report"}\n')
            viewer.stdin.flush()
            while got is None:
                line = json.loads(viewer.stdout.readline())
                got = line.get("report")
            viewer.kill()
        safety.stop(b)
        for s in subs:
            safety.lines(s)
        safety.stop(d)
        rep = safety.report(tmp, name)
        for stream in ["cam", "lid"]:
            lat = rep[f"egress {stream}/perturbed"]["latency"]
            print(f"  {name:8} {stream}: {lat['p50_ms']:.2f} / {lat['p99_ms']:.2f} ({lat['n']} frames)")
        if got:
            rates = {t: round(v["rate_hz"], 1) for t, v in sorted(got.items())
                     if t.endswith("/image") or t.endswith("/points")}
            print(f"    viewer received (Hz): {rates}")
        print(f"    CPU (% of a core over the run): bridge {bridge_cpu / a.seconds * 100:.0f}, "
              f"viewer {viewer_cpu / a.seconds * 100:.0f}")


def record(r, tmp, a):
    print("## recorder: CPU per stream (cores, user+system) and bag size per minute, synthetic camera at 30 Hz")
    for w, h in [(800, 503), (1920, 1208)]:
        for comp in ["zstd:1", "zstd:3", "lz4", "none"]:
            out = tmp / f"rec-{w}-{comp.replace(':', '')}"
            shutil.rmtree(out, ignore_errors=True)
            src = tmp / f"src-{w}.toml"
            src.write_text(f'[bridge]\nname = "src"\n[[synthetic.camera]]\nstream = "cam"\n'
                           f'width = {w}\nheight = {h}\nrate_hz = 30\nprerender = 30\n')
            rec = subprocess.Popen([str(r.bins / "perturb-bridge"), "record", "--out", str(out),
                                    "--stream", "cam=image", "--raw-only", "--seconds",
                                    str(a.seconds), "--compression", comp], env=r.env,
                                   stdout=subprocess.DEVNULL,
                                   stderr=open(tmp / "record.log", "a"))
            time.sleep(1.5)
            s = r.bridge(src)
            _, status, ru = os.wait4(rec.pid, 0)
            rec.returncode = status
            safety.stop(s)
            size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
            meta = (out / "metadata.yaml").read_text() if (out / "metadata.yaml").exists() else ""
            n = next((line.split(":")[1].strip() for line in meta.splitlines()
                      if "message_count" in line), "?")
            cpu = ru.ru_utime + ru.ru_stime
            # Per second of stream recorded (the source starts after the recorder).
            stream_s = int(n) / 30 if n.isdigit() and int(n) else a.seconds
            print(f"  {w}x{h} {comp:6}: recorder CPU {cpu / stream_s * 100:5.1f} % of a core, "
                  f"{size / 1e6 * 60 / stream_s:8.1f} MB per minute ({n} frames, "
                  f"{size / 1e6:.1f} MB, {cpu:.2f} s CPU)")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default=str(ROOT / "target/release"))
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--only", choices=["view", "record"])
    ap.add_argument("--order", default="none,idle,light,view,none2,light2",
                    help="runs in this order: none* without [view], idle* with [view] and no "
                    "viewer, light* with a viewer that counts without decoding, view* with a "
                    "viewer that decodes every message (JPEG, protobuf, JSON schemas)")
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="perturb-view-"))
    r = safety.Run(a.bin, tmp)
    try:
        if a.only in (None, "view"):
            view(r, tmp, a)
        if a.only in (None, "record"):
            record(r, tmp, a)
    finally:
        r.close()
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
