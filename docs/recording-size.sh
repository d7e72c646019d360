#!/usr/bin/env bash
# Size of a recording per hour (docs/recording.md, "Compression"). Usage (debug build first,
# `cargo build -p thrusterctl -p thrusterd -p thruster-sim`):
#   bash docs/recording-size.sh RATE_HZ SECONDS [record flags, e.g. --compression none]
# A real-time session on a private namespace: `thrusterctl record` started first, then
# `thrusterd run` (the shipped defaults: telemetry every 10th sample) and `thruster-sim run
# --realtime --rate RATE_HZ` (AMOUR-5, realistic noise); an estimation is requested after 2 s,
# so the session has pulses, a model and control. Prints the file size and that size scaled to
# one hour.
set -eu
ROOT=$(cd "$(dirname "$0")/.." && pwd)
B=$ROOT/target/debug
RATE=$1
SECS=$2
shift 2
DIR=/tmp/recsize-$RATE-$$
mkdir -p "$DIR" && cd "$DIR"
NS=rsz$$
"$B/thrusterctl" --namespace "$NS" record --out "$DIR/s.mcap" "$@" > rec.log 2>&1 &
REC=$!
while [ ! -e "$DIR/s.mcap" ]; do sleep 0.05; done
"$B/thrusterd" run --namespace "$NS" --state-dir "$DIR/state" --thrusters 5 > d.log 2>&1 &
D=$!
"$B/thruster-sim" run --namespace "$NS" --vehicle "$ROOT/config/vehicles/amour5.toml" \
  --noise realistic --realtime --rate "$RATE" --duration "$SECS" > s.log 2>&1 &
S=$!
sleep 2
"$B/thrusterctl" --namespace "$NS" estimate > est.log 2>&1 || true
wait $S
kill -INT $REC; wait $REC || true
kill -TERM $D; wait $D || true
BYTES=$(stat -c %s "$DIR/s.mcap")
echo "rate ${RATE} Hz, ${SECS} s, flags '$*': ${BYTES} bytes; per hour $(python3 -c "print(f'{$BYTES * 3600 / $SECS / 1e6:.1f}')") MB"
tail -n 1 rec.log
[ -n "${KEEP:-}" ] && cp "$DIR/s.mcap" "$KEEP"
rm -rf "$DIR"
