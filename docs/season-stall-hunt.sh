#!/bin/bash
# Runs the CI season again and again and keeps every run that stalls, with what its processes
# held at that moment (docs/reliability.md, "The stall found": 3 stalls in 140 runs of 749827a).
#
#   cargo build --release -p thrusterd -p thrusterctl -p thruster-sim -p system-tests --bins
#   mkdir -p /tmp/bins && cp target/release/{thrusterd,thrusterctl,thruster-sim,season} /tmp/bins/
#   docs/season-stall-hunt.sh /tmp/bins /tmp/hunt 100
#
# A run not done in LIMIT s (default 150; a run takes about 50) is a stall: its folder keeps
# each child's /proc fd listing, unix sockets and threads' wait channels, 3 s of strace, ss -xpa,
# /proc/net/unix, the namespace's files and a hex dump of every listener's shared state
# (/dev/shm/*event_mgmt*: byte 0x28 is the notification state, 2 = notified). Passing runs are
# deleted; OUT/log has a line per run (with the daemon's count of IMU samples read without their
# notification, `imu_unnotified_wakeups`, where the build logs it).
BIN=$1; OUT=$2; RUNS=${3:-100}; LIMIT=${LIMIT:-150}
mkdir -p "$OUT"
for i in $(seq 1 "$RUNS"); do
  out=$OUT/run$i; rm -rf "$out"; mkdir -p "$out"
  start=$(date +%s)
  THRUSTER_BIN_DIR=$BIN RUST_LOG=info setsid "$BIN/season" --hours 0.25 --scale 0.0625 --pace 20 \
    --out "$out" > "$out/stdout" 2> "$out/stderr" &
  pid=$!
  t=0
  while kill -0 $pid 2>/dev/null && [ $t -lt "$LIMIT" ]; do sleep 1; t=$((t+1)); done
  if kill -0 $pid 2>/dev/null; then
    echo "run $i STALL at $(date)" >> "$OUT/log"
    d=$out/diag; mkdir -p "$d"
    for c in $(pgrep -P $pid); do
      tr '\0' ' ' < /proc/$c/cmdline > "$d/$c.cmd"
      ls -l /proc/$c/fd > "$d/$c.fd" 2>&1
      for tk in /proc/$c/task/*; do echo "$tk $(cat $tk/comm) $(cat $tk/wchan)"; done > "$d/$c.tasks"
      timeout 3 strace -f -tt -p $c -o "$d/$c.strace" 2>/dev/null &
    done
    ss -xpa > "$d/ss.txt" 2>&1
    cat /proc/net/unix > "$d/net_unix.txt"
    ls -laR /tmp/iceoryx2/thr > "$d/root.txt" 2>&1
    for f in /dev/shm/*event_mgmt*; do echo "== $f"; xxd "$f" | head -8; done > "$d/event_mgmt.txt" 2>&1
    sleep 4
    kill -INT -$pid 2>/dev/null; sleep 5; kill -KILL -$pid 2>/dev/null
    wait $pid
  else
    wait $pid; rc=$?
    echo "run $i rc=$rc $(( $(date +%s)-start )) s $(grep -o 'verdict: [A-Z]*' "$out/stdout") $(grep -o 'imu_unnotified_wakeups=[0-9]*' "$out/thrusterd.log")" >> "$OUT/log"
    [ $rc -eq 0 ] && rm -rf "$out"
  fi
done
