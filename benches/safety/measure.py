#!/usr/bin/env python3
"""Measures the safety envelope through the real pipeline on loopback (the figures of
docs/safety.md): a synthetic camera (1920x1208 rgb8, 30 Hz) and VLP-32C (10 Hz) -> perturb-bridge ->
perturbd -> perturb-bridge -> rospy subscribers on ROS 1, with a real roscore.

  python3 benches/safety/measure.py [--bin target/release] [--seconds 20]

1. healthy pipeline: the egress's latency (sensor source -> ROS 1 write returned, the bridge's
   report) and the rospy subscriber's, with the deadline machinery (on_late = "raw") and without
   it (on_late = "wait"), one after the other;
2. faults: kill -9 of perturbd, restart 2 s later, then SIGSTOP for 2 s: frames received by the
   ADS side out of frames sent, the largest gap between two received frames, the fallbacks by
   reason, with the default deadline (one frame period) and with deadline_ms = 10;
3. restart-to-first-frame of the bridge itself after kill -9 (the ADS's longest gap when the
   bridge is the process that dies: it is the publisher).

Needs Debian's roscore and rospy (/usr/bin/python3) and the release binaries.
"""
import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PEER = ROOT / "tests/tests/ros1_peer.py"


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    p = s.getsockname()[1]
    s.close()
    return p


def mono_ns():
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


class Run:
    def __init__(self, bins, tmp):
        self.bins, self.tmp = Path(bins), Path(tmp)
        port = free_port()
        self.env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}/",
                        ROS_HOSTNAME="127.0.0.1", ROS_HOME=str(self.tmp / "ros"),
                        PERTURB_IOX2_PREFIX=f"meas_{os.getpid()}_",
                        PERTURB_IOX2_ROOT=str(self.tmp / "iox2"))
        self.env.pop("ROS_IP", None)
        (self.tmp / "ros").mkdir(exist_ok=True)
        self.roscore = subprocess.Popen(["roscore", "-p", str(port)], env=self.env,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                        start_new_session=True)
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), 0.2).close()
                break
            except OSError:
                time.sleep(0.1)

    def daemon(self, cfg):
        p = subprocess.Popen([str(self.bins / "perturbd"), "--config", str(cfg), "--report",
                              str(self.tmp / "perturbd-report.json")], env=self.env,
                             stdout=subprocess.DEVNULL, stderr=open(self.tmp / "perturbd.log", "a"))
        while subprocess.run([str(self.bins / "perturb"), "ctl", "status", "--timeout", "0.5"],
                             env=self.env, capture_output=True).returncode != 0:
            time.sleep(0.1)
        return p

    def bridge(self, cfg):
        return subprocess.Popen([str(self.bins / "perturb-bridge"), "--config", str(cfg)],
                                env=self.env, stdout=subprocess.DEVNULL,
                                stderr=open(self.tmp / "bridge.log", "a"))

    def sub(self, topic, ty, name):
        p = subprocess.Popen(["/usr/bin/python3", str(PEER), "sub", "--topic", topic, "--type", ty,
                              "--count", "10000000", "--timeout", "600", "--no-hash", "--name",
                              name], env=self.env, stdout=subprocess.PIPE, text=True)
        assert "ready" in p.stdout.readline()
        return p

    def close(self):
        os.killpg(self.roscore.pid, signal.SIGINT)
        self.roscore.wait()


def lines(p):
    p.send_signal(signal.SIGKILL)
    out = p.stdout.read()
    return [json.loads(line) for line in out.splitlines() if line.startswith("{")]


def stop(p):
    p.send_signal(signal.SIGINT)
    p.wait(20)


def pct(v, q):
    v = sorted(v)
    return v[min(len(v) - 1, int(q * len(v)))] if v else float("nan")


def bridge_cfg(tmp, name, on_late, deadline=None):
    extra = f"\ndeadline_ms = {deadline}" if deadline else ""
    cfg = tmp / f"bridge-{name}.toml"
    cfg.write_text(f"""[bridge]
name = "meas_{name}"
report = "{tmp}/report-{name}.json"
[ros1]
hostname = "127.0.0.1"
[[synthetic.camera]]
stream = "cam"
width = 1920
height = 1208
rate_hz = 30
prerender = 10
[[synthetic.lidar]]
stream = "lid"
rate_hz = 10
prerender = 4
[[egress]]
stream = "cam"
topic = "/ads/camera"
transport = "ros1"
on_late = "{on_late}"{extra}
[[egress]]
stream = "lid"
topic = "/ads/lidar"
transport = "ros1"
on_late = "{on_late}"{extra}
""")
    return cfg


def report(tmp, name):
    rep = json.loads((tmp / f"report-{name}.json").read_text())
    return {r["name"].split(" ->")[0]: r for r in rep}


def gaps(frames):
    t = sorted(f["t_arrival_ns"] for f in frames)
    return max((b - a for a, b in zip(t, t[1:])), default=0) / 1e6


def bayer(r, tmp, a):
    """The vehicle's cameras: bayer_rggb8 at 2064x1544, 30 Hz, from a roscpp publisher (the test
    build of tests/support/ros1_cpp_pub.cpp) through the bridge's ROS 1 ingress, perturbd (off,
    then C-A1 severity 2: demosaic, perturbation, mosaic back) and the ROS 1 egress to a rospy
    subscriber: the bridge's egress latency (ingress -> ROS 1 write returned) p50 / p99."""
    cpp = ROOT / "target/roscpp/ros1_cpp_pub"
    if not cpp.exists():
        print(f"  {cpp} missing: run the ROS 1 tests once (they build it)")
        return
    print("## bayer_rggb8 2064x1544 at 30 Hz, ROS 1 in and out: egress latency p50 / p99 ms")
    for label, pert in [("off", ""), ("C-A1 s2", 'perturbation = { id = "C-A1", severity = 2, seed = 1 }\n')]:
        cfg = tmp / "perturbd-bayer.toml"
        cfg.write_text(f'[[streams]]\nname = "cam"\nmodality = "camera"\n{pert}')
        d = r.daemon(cfg)
        bcfg = tmp / "bridge-bayer.toml"
        bcfg.write_text(f"""[bridge]
name = "meas_bayer"
report = "{tmp}/report-bayer.json"
[ros1]
hostname = "127.0.0.1"
[[ingress]]
topic = "/sensors/cam"
type = "image"
stream = "cam"
transport = "ros1"
[[egress]]
stream = "cam"
topic = "/ads/camera"
transport = "ros1"
""")
        sub = r.sub("/ads/camera", "image", "cam")
        b = r.bridge(bcfg)
        time.sleep(2)
        p = subprocess.run([str(cpp), "/sensors/cam", str(int(30 * a.seconds)), "30", "2064",
                            "1544", "bayer_rggb8", "1000"], env=r.env, capture_output=True)
        time.sleep(1)
        stop(b)
        got = lines(sub)
        stop(d)
        rep = json.loads((tmp / "report-bayer.json").read_text())
        eg = next(x for x in rep if x["name"].startswith("egress"))
        ing = next(x for x in rep if x["name"].startswith("ingress"))
        lat = eg["latency"]
        enc = {f.get("encoding") for f in got}
        print(f"  perturbation {label}: {lat['p50_ms']:.2f} / {lat['p99_ms']:.2f} ({lat['n']} frames; "
              f"ingress received {ing['received']}, rospy got {len(got)} {sorted(enc)}; "
              f"roscpp exit {p.returncode})")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default=str(ROOT / "target/release"))
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--only", choices=["healthy", "faults", "restart", "bayer"])
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="perturb-safety-"))
    daemon_cfg = tmp / "perturbd.toml"
    daemon_cfg.write_text('[[streams]]\nname = "cam"\nmodality = "camera"\n'
                          'perturbation = { id = "C-A1", severity = 2, seed = 1 }\n\n'
                          '[[streams]]\nname = "lid"\nmodality = "lidar"\nsensor = "vlp32c"\n'
                          'perturbation = { id = "L-B1", severity = 1, seed = 1 }\n')
    r = Run(a.bin, tmp)
    try:
        if a.only == "bayer":
            return bayer(r, tmp, a)
        print("## healthy pipeline: egress latency (source -> ROS 1 write returned), p50 / p99 ms")
        for mode in ([] if a.only not in (None, "healthy") else ["raw", "wait"]):
            d = r.daemon(daemon_cfg)
            subs = [r.sub("/ads/camera", "image", "cam"), r.sub("/ads/lidar", "cloud", "lid")]
            b = r.bridge(bridge_cfg(tmp, mode, mode))
            time.sleep(a.seconds)
            stop(b)
            got = [lines(s) for s in subs]
            stop(d)
            rep = report(tmp, mode)
            for stream in ["cam", "lid"]:
                eg = rep[f"egress {stream}/perturbed"]
                lat = eg["latency"]
                print(f"  on_late = {mode:5} {stream}: {lat['p50_ms']:.2f} / {lat['p99_ms']:.2f} "
                      f"({lat['n']} frames; fallback {eg['fallback_raw']})")
            for name, g in zip(["cam", "lid"], got):
                print(f"    rospy {name}: {len(g)} frames")
        print("## faults: kill -9 of perturbd (restart after 2 s), then SIGSTOP 2 s")
        for name, deadline in ([] if a.only not in (None, "faults") else [("fault", None), ("fault10", 10)]):
            d = r.daemon(daemon_cfg)
            subs = [r.sub("/ads/camera", "image", "cam"), r.sub("/ads/lidar", "cloud", "lid")]
            b = r.bridge(bridge_cfg(tmp, name, "raw", deadline))
            time.sleep(4)
            d.kill()
            d.wait()
            time.sleep(2)
            d = r.daemon(daemon_cfg)
            time.sleep(3)
            d.send_signal(signal.SIGSTOP)
            time.sleep(2)
            d.send_signal(signal.SIGCONT)
            time.sleep(3)
            stop(b)
            got = [lines(s) for s in subs]
            stop(d)
            rep = report(tmp, name)
            sent = {"cam": rep["synthetic camera 1920x1208 @ 30 Hz"]["forwarded"],
                    "lid": rep["synthetic VLP-32C @ 10 Hz"]["forwarded"]}
            for stream, g in zip(["cam", "lid"], got):
                eg = rep[f"egress {stream}/perturbed"]
                print(f"  deadline {deadline or 'one period'}: {stream}: egress published "
                      f"{eg['forwarded']} of {sent[stream]} sent; rospy received {len(g)}; "
                      f"largest gap {gaps(g):.1f} ms; fallback {eg['fallback_raw']}; "
                      f"lost {eg['lost_by_cause']}")
        print("## restart-to-first-frame of the bridge after kill -9")
        if a.only not in (None, "restart"):
            return
        d = r.daemon(daemon_cfg)
        cfg = bridge_cfg(tmp, "restart", "raw")
        sub = r.sub("/ads/camera", "image", "cam")
        b = r.bridge(cfg)
        time.sleep(4)
        t_kill = mono_ns()
        b.kill()
        b.wait()
        b = r.bridge(cfg)
        time.sleep(4)
        stop(b)
        got = lines(sub)
        stop(d)
        t = sorted(f["t_arrival_ns"] for f in got)
        # The outage: the largest gap around the kill (frames already in the subscriber's
        # socket still arrive just after it).
        window = [(a, b) for a, b in zip(t, t[1:]) if b > t_kill - 500_000_000]
        if window:
            a, b = max(window, key=lambda w: w[1] - w[0])
            print(f"  camera: no frame for {(b - a) / 1e6:.0f} ms around the kill (the new bridge "
                  f"restarted at once, as systemd Restart=always / roslaunch respawn do; first "
                  f"frame {(b - t_kill) / 1e6:.0f} ms after the kill)")
        else:
            print("  camera: no frame after the restart")
    finally:
        r.close()


if __name__ == "__main__":
    sys.exit(main())
