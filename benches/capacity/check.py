#!/usr/bin/env python3
"""Checks `perturb bench --capacity` against the live pipeline on this machine.

For one stream kind (a camera at 800x503, 30 Hz, with PERTURBATION, the frames the load bench
publishes), asks `perturb bench --capacity` how many such streams N cores sustain, then runs
`perturb-e2e-bench load` for SECONDS with that many streams and with twice as many, on N cores
(`taskset` pins the daemon and the load bench's sources together), and prints the drops.

    tests/loopback-only python3 benches/capacity/check.py --bin target/release --cores 1 2

The model holds when the predicted count drops nothing and twice it drops frames.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile


def config(n, pid, sev):
    out = []
    for i in range(n):
        out.append(
            f'[[streams]]\nname = "cam{i}"\nmodality = "camera"\n'
            f'perturbation = {{ id = "{pid}", severity = {sev}, seed = 1 }}\n'
        )
    return "[daemon]\nstats_interval_s = 10\n\n" + "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default="target/release")
    ap.add_argument("--id", default="C-B4")
    ap.add_argument("--severity", type=int, default=5)
    ap.add_argument("--cores", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--seconds", type=float, default=60)
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="perturb-capacity-")
    one = os.path.join(tmp, "one.toml")
    with open(one, "w") as f:
        f.write(config(1, a.id, a.severity))
    rows = []
    for n in a.cores:
        cpus = ",".join(str(c) for c in range(n))
        rep = subprocess.run(
            ["taskset", "-c", cpus, os.path.join(a.bin, "perturb"), "bench", "--capacity", one,
             "--width", "800", "--height", "503", "--frames", "20", "--json"],
            check=True, capture_output=True, text=True)
        r = json.loads(rep.stdout)
        s = r["streams"][0]
        k = dict((c, m) for c, m in s["alone"])[n]
        print(f"{n} core(s): {a.id} s{a.severity} at 800x503 costs {s['cost_p50_ms']:.2f} ms "
              f"(p99 {s['cost_p99_ms']:.2f}), {s['load_cores']:.3f} cores at 30 Hz; predicted {k} streams",
              flush=True)
        for count in (k, 2 * k):
            path = os.path.join(tmp, f"n{count}.toml")
            with open(path, "w") as f:
                f.write(config(count, a.id, a.severity))
            run = subprocess.run(
                ["taskset", "-c", cpus, os.path.join(a.bin, "perturb-e2e-bench"), "load",
                 "--seconds", str(a.seconds), "--config", path],
                capture_output=True, text=True)
            m = re.search(r"published (\d+), received (\d+), daemon published (\d+), dropped (\d+)", run.stdout)
            if run.returncode != 0 or not m:
                print(run.stdout, run.stderr, file=sys.stderr)
                sys.exit(f"the load run of {count} streams failed")
            pub, rec, out, drop = map(int, m.groups())
            cpu = re.search(r"CPU: perturbd (\d+)%", run.stdout)
            rows.append((n, count, pub, out, drop, cpu.group(1) if cpu else "?"))
            print(f"  {count:>3} streams for {a.seconds:.0f} s: sources published {pub}, daemon published {out}, "
                  f"dropped {drop}, perturbd CPU {rows[-1][5]}% of a core", flush=True)
    print("\n| cores | streams | published | daemon published | dropped | perturbd CPU |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print("| %d | %d | %d | %d | %d | %s%% |" % r)


if __name__ == "__main__":
    main()
