#!/usr/bin/env python3
"""The table of docs/study.md "The IMU off the centre and moving water (issue 32)", over seeds.

Runs `thrusterctl demo --json --hold-s 0 --noise realistic` (release build, lockstep, stepped:
the same figures on any machine) for every case and seed, and prints one markdown row per
case: errors against the simulator's truth and the daemon's bounds as mean +- sd [min-max],
the worst coverage (error / bound), the IMU position found, refusals with their reason.

    python3 docs/imu-water-measure.py [SEEDS]        # seeds 1..SEEDS, default 10

Needs `cargo build --release -p thrusterctl -p thrusterd -p thruster-sim` first.
"""
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CTL = os.path.join(ROOT, "target", "release", "thrusterctl")
OFF = "0.15,0.05,-0.10"
TOLD = "[estimator]\nimu_position_m = [0.15, 0.05, -0.10]\n"

CASES = [
    ("AMOUR-5, IMU at the CO", "amour5", []),
    ("AMOUR-5, `--imu-position %s`" % OFF, "amour5", ["--imu-position", OFF]),
    ("AMOUR-5, the same, told", "amour5", ["--imu-position", OFF, "TOLD"]),
    ("eight_vectored, IMU at the CO", "eight_vectored", []),
    ("eight_vectored, `--imu-position %s`" % OFF, "eight_vectored", ["--imu-position", OFF]),
    ("eight_vectored, the same, told", "eight_vectored", ["--imu-position", OFF, "TOLD"]),
    ("AMOUR-5, `--water current`", "amour5", ["--water", "current"]),
    ("eight_vectored, `--water current`", "eight_vectored", ["--water", "current"]),
    ("AMOUR-5, `--water moderate`", "amour5", ["--water", "moderate"]),
    ("eight_vectored, `--water moderate`", "eight_vectored", ["--water", "moderate"]),
    ("AMOUR-5, `--water rough`", "amour5", ["--water", "rough"]),
    ("eight_vectored, `--water rough`", "eight_vectored", ["--water", "rough"]),
]


def stats(values, digits=3):
    if not values:
        return ""
    mean = statistics.fmean(values)
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    f = "%%.%df" % digits
    return (f + " ± " + f + " [" + f + "-" + f + "]") % (mean, sd, min(values), max(values))


def run(vehicle, extra, seed, told_path):
    args = [CTL, "demo", "--json", "--hold-s", "0", "--noise", "realistic", "--seed", str(seed),
            "--vehicle", os.path.join(ROOT, "config", "vehicles", vehicle + ".toml")]
    for a in extra:
        args += ["--daemon-config", told_path] if a == "TOLD" else [a]
    out = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=900)
    try:
        return json.loads(out.stdout)
    except json.JSONDecodeError:
        sys.exit("%s: no JSON (exit %d)\n%s" % (" ".join(args), out.returncode, out.stderr[-2000:]))


def main():
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    with tempfile.TemporaryDirectory() as tmp:
        told = os.path.join(tmp, "told.toml")
        with open(told, "w") as f:
            f.write(TOLD)
        print("seeds 1-%d, realistic IMU, mean ± sd [min-max]\n" % seeds)
        print("| case | err_rot | err_acc | bound rot | bound acc | worst coverage | "
              "position found, m | refused | vehicle s |")
        print("|---|---|---|---|---|---|---|---|---|")
        for name, vehicle, extra in CASES:
            runs = [run(vehicle, extra, s, told) for s in range(1, seeds + 1)]
            made = [r for r in runs if "err_rot" in r]
            refused = [r["refused"] for r in runs if "refused" in r]
            col = lambda k: stats([r[k] for r in made])
            cover = max((max(r["err_rot"] / r["bound_rot"], r["err_acc"] / r["bound_acc"])
                         for r in made), default=None)
            pos = [r["imu_learned_m"] for r in made if r.get("imu_learned_m")]
            for text in refused:
                m = re.search(r"IMU found at \(([-\d.]+), ([-\d.]+), ([-\d.]+)\)", text)
                if m:
                    pos.append([float(x) for x in m.groups()])
            where = " ".join(
                "%s %.3f..%.3f" % (axis, min(p[i] for p in pos), max(p[i] for p in pos))
                for i, axis in enumerate("xyz")) if pos else ""
            rates = [float(m.group(1)) for t in refused
                     for m in [re.search(r"([\d.]+) rad/s of rotation unexplained", t)] if m]
            why = "%d of %d" % (len(refused), len(runs))
            if rates:
                why += " (%.3f-%.3f rad/s unexplained)" % (min(rates), max(rates))
            elif refused:
                why += " (IMU position)" if all("IMU found" in t for t in refused) else ""
            print("| %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
                name, col("err_rot"), col("err_acc"), col("bound_rot"), col("bound_acc"),
                "%.2f" % cover if cover is not None else "", where, why,
                stats([r["vehicle_seconds"] for r in made], 2)), flush=True)


if __name__ == "__main__":
    main()
