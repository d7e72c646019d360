#!/usr/bin/env bash
# Recorder figures of docs/recording.md. Usage: bash docs/recording-measure.sh (debug build first).
# Recorder at 1 kHz for 60 vehicle-s (real time): daemon (telemetry every sample), sim, recorder.
set -u
ROOT=$(cd "$(dirname "$0")/.." && pwd)
B=$ROOT/target/debug
mkdir -p /tmp/recmeasure && cd /tmp/recmeasure && rm -rf state ./*.mcap
NS=recm$$
printf '[telemetry]\nevery_n = 1\n' > d.toml
$B/thrusterctl --namespace $NS record --out /tmp/recmeasure/m.mcap > rec.log 2>&1 &
REC=$!
while [ ! -e /tmp/recmeasure/m.mcap ]; do sleep 0.05; done
$B/thrusterd run --namespace $NS --state-dir /tmp/recmeasure/state --config d.toml --thrusters 5 > d.log 2>&1 &
D=$!
$B/thruster-sim run --namespace $NS --vehicle $ROOT/config/vehicles/amour5.toml --realtime --rate 1000 --duration 60 > s.log 2>&1
read -r _ _ _ _ _ _ _ _ _ _ _ _ _ u s _ < /proc/$REC/stat
echo "recorder cpu ticks user $u sys $s (CLK_TCK $(getconf CLK_TCK))" > cpu.txt
ps -o etimes= -p $REC >> cpu.txt
kill -INT $REC; wait $REC; echo "rec exit $?" >> cpu.txt
kill -TERM $D; wait $D; echo "daemon exit $?" >> cpu.txt
ls -la /tmp/recmeasure/*.mcap >> cpu.txt
