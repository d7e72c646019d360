#!/usr/bin/env bash
# The control thread's mallocs, docs/performance.md ("The loop around the machine does
# allocate"): a uprobe on glibc's malloc, recorded with call stacks for thrusterd's main thread
# (the control loop) while the real-time demo holds attitude, then counted by caller. Needs
# root (perf probe) and a release build:
#   cargo build --release -p thrusterd -p thruster-sim -p thrusterctl --bins
# Usage: sudo bash docs/alloc-probe.sh [SECONDS recorded, default 3] [SECONDS before, default 15]
set -u
ROOT=$(cd "$(dirname "$0")/.." && pwd)
REC_S=${1:-3}
WAIT_S=${2:-15}
LIBC=$(ldconfig -p | awk '/libc\.so\.6 .*x86-64/ {print $NF; exit}')
W=$(mktemp -d /tmp/alloc-probe.XXXXXX)
trap 'perf probe -q -d probe_libc:malloc 2>/dev/null; rm -rf "$W"' EXIT
perf probe -q -x "$LIBC" --add malloc || { echo "perf probe failed (root? uprobes?)"; exit 1; }
cd "$ROOT"
./target/release/thrusterctl demo --realtime --noise realistic --hold-s 40 --json >"$W/demo.json" 2>"$W/demo.err" &
DEMO=$!
P=
for _ in $(seq 1 100); do P=$(pgrep -n -x thrusterd) && break; sleep 0.1; done
[ -n "$P" ] || { echo "no thrusterd started"; exit 1; }
sleep "$WAIT_S" # the estimate, then the hold
perf record -q --call-graph dwarf,16384 -e probe_libc:malloc -t "$P" -o "$W/perf.data" -- sleep "$REC_S" 2>/dev/null
perf script -i "$W/perf.data" 2>/dev/null >"$W/stacks.txt"
wait $DEMO
python3 - "$W/stacks.txt" "$REC_S" <<'PY'
import collections, re, sys
stacks = [s for s in open(sys.argv[1]).read().split("\n\n") if s.strip()]
skip = ("malloc", "alloc::", "__rust_alloc", "__rdl_alloc", "raw_vec", "RawVec", "core::ptr")
by = collections.Counter()
for s in stacks:
    frames = []
    for line in s.split("\n")[1:]:
        m = re.match(r"\s*[0-9a-f]+ (.+) \(", line)
        if m and not any(x in m.group(1) for x in skip):
            frames.append(re.sub(r"\+0x[0-9a-f]+$", "", m.group(1))[:100])
        if len(frames) == 2:
            break
    by[" <- ".join(frames)] += 1
print(f"{len(stacks)} mallocs on the control thread in {sys.argv[2]} s")
for k, v in by.most_common(12):
    print(f"{v:6d}  {k}")
PY
