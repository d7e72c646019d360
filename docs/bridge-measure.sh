#!/usr/bin/env bash
# Bridge figures of docs/recording.md: the daemon's IMU -> thrust latency at 1 kHz as the
# simulator measures it (its --stats-file histogram), alone and with thruster-bridge attached
# (recording to MCAP + live view with one Foxglove client subscribed to every channel), runs
# alternated; the bridge's CPU from /proc. Release build first:
#   cargo build --release -p thrusterd -p thruster-sim -p thruster-bridge --bins
# The client's packages: target/node-ws/node_modules (made by `cargo test -p system-tests --test
# bridge`) or NODE_MODULES=... Usage: bash docs/bridge-measure.sh [SECONDS per run, default 20]
set -u
ROOT=$(cd "$(dirname "$0")/.." && pwd)
B=$ROOT/target/release
MODS=${NODE_MODULES:-$ROOT/target/node-ws/node_modules}
SECS=${1:-20}
W=/tmp/bridgemeasure
rm -rf $W && mkdir -p $W && cd $W
for round in 1 2; do
  for mode in alone bridge; do
    NS=brm$$r$round${mode:0:1}
    BR=; CL=
    if [ $mode = bridge ]; then
      $B/thruster-bridge --namespace $NS --ws 127.0.0.1:0 --record $W/$NS.mcap > $NS.bridge.log 2>&1 &
      BR=$!
      until grep -q "live view on ws://" $NS.bridge.log; do sleep 0.05; done
      PORT=$(grep -o "ws://127.0.0.1:[0-9]*" $NS.bridge.log | head -1 | sed 's/.*://')
      NODE_PATH=$MODS node $ROOT/tests/node/bridge_client.js ws://127.0.0.1:$PORT $((SECS + 30)) --watch > $NS.client.json 2>&1 &
      CL=$!
    fi
    $B/thrusterd run --namespace $NS --state-dir $W/$NS.state --thrusters 5 > $NS.d.log 2>&1 &
    D=$!
    sleep 0.5
    if [ -n "$BR" ]; then read -r _ _ _ _ _ _ _ _ _ _ _ _ _ u0 s0 _ < /proc/$BR/stat; T0=$(date +%s.%N); fi
    $B/thruster-sim run --namespace $NS --vehicle $ROOT/config/vehicles/amour5.toml --realtime \
        --rate 1000 --duration $SECS --stats-file $W/$NS.stats > $NS.s.log 2>&1
    if [ -n "$BR" ]; then
      read -r _ _ _ _ _ _ _ _ _ _ _ _ _ u1 s1 _ < /proc/$BR/stat; T1=$(date +%s.%N)
      echo "$round $mode cpu_ticks $((u1 + s1 - u0 - s0)) wall $(echo "$T1 - $T0" | bc) clk $(getconf CLK_TCK)" >> cpu.txt
      kill -TERM $CL; wait $CL
      kill -INT $BR; wait $BR
    fi
    kill -TERM $D; wait $D
    echo "$round $mode $NS" >> runs.txt
  done
done
python3 - "$W" <<'PY'
import json, sys, os
w = sys.argv[1]
def upper(i):
    if i < 1000: return i + 1.0
    if i < 1990: return 1000.0 + (i - 1000 + 1) * 100
    if i < 2980: return 100000.0 + (i - 1990 + 1) * 10000
    return float("inf")
def stats(path):
    counts, n, s, mx = {}, 0, 0, 0
    lines = [json.loads(l) for l in open(path)]
    for l in lines[2:]:  # the first 2 s: start-up
        h = l["latency"]
        for i, c in h["buckets"]:
            counts[i] = counts.get(i, 0) + c
        n += h["count"]; s += h["sum_ns"]; mx = max(mx, h["max_ns"])
    def q(p):
        rank, seen = max(1, int(-(-p * n // 1))), 0
        for i in sorted(counts):
            seen += counts[i]
            if seen >= rank: return min(upper(i), mx / 1e3)
    un = lines[-1]["unanswered"]
    return n, q(0.5), q(0.99), q(0.999), s / n / 1e3, mx / 1e3, un
cpu = {}
for l in open(os.path.join(w, "cpu.txt")):
    r, m, _, t, _, wall, _, clk = l.split()
    cpu[(r, m)] = int(t) / int(clk) / float(wall) * 100
print("| run | daemon | samples | p50 us | p99 us | p99.9 us | mean us | max us | unanswered | bridge CPU % of one core |")
print("|---|---|---|---|---|---|---|---|---|---|")
agg = {"alone": [], "bridge": []}
for l in open(os.path.join(w, "runs.txt")):
    r, m, ns = l.split()
    st = stats(os.path.join(w, ns + ".stats"))
    agg[m].append(st)
    c = cpu.get((r, m))
    print(f"| {r} | {m} | {st[0]} | {st[1]:.0f} | {st[2]:.0f} | {st[3]:.0f} | {st[4]:.1f} | {st[5]:.0f} | {st[6]} | {'' if c is None else f'{c:.1f}'} |")
mean = lambda v, i: sum(x[i] for x in v) / len(v)
print(f"with/alone: p50 {mean(agg['bridge'],1)/mean(agg['alone'],1):.3f}, p99 {mean(agg['bridge'],2)/mean(agg['alone'],2):.3f}, mean {mean(agg['bridge'],4)/mean(agg['alone'],4):.3f}")
PY
grep -h "; lost" $W/*.bridge.log | sed 's/^.*INFO thruster_bridge: //'
