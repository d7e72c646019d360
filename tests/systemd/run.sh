#!/usr/bin/env bash
# The units under a real systemd: boots systemd 252 in a container (systemd-nspawn), installs
# thrusterd exactly as the README's "Install on a vehicle" section says, with thruster-sim in
# real time standing in for thruster-hw (a runtime drop-in), and checks what an operator and
# systemd rely on. Any failed check exits non-zero naming the check and keeps the container's
# journal in $THRUSTERD_CI_LOGS (default /tmp/thrusterd-systemd-test-logs). Nothing is left
# running or mounted. One test-bed setting differs from the shipped configs: imu_timeout_ms
# (see below and docs/reliability.md).
#
#   sudo tests/systemd/run.sh          (root: nspawn, mounts; CI runs it from .ci/run)
#
# Needs: Debian/Ubuntu with apt (installs systemd-container and mmdebstrap if missing), the
# Debian mirror apt uses (once, for the container's rootfs, cached in $THRUSTERD_CI_CACHE,
# default /var/cache/thrusterd-ci), a Rust toolchain (builds the debug binaries).
set -euo pipefail

REPO=$(cd "$(dirname "$0")/../.." && pwd)
CACHE=${THRUSTERD_CI_CACHE:-/var/cache/thrusterd-ci}
# Bump the suffix when the package list changes: a new rootfs is built beside the old one.
ROOTFS=$CACHE/rootfs-bookworm-v1
PACKAGES=systemd,systemd-sysv,dbus
NS=thrusterd
IPC=/run/thrusterd
T0=$EPOCHREALTIME

elapsed() { awk -v a="$T0" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.1f", b - a }'; }
say() { echo "[systemd-test $(elapsed) s] $*"; }
# On a failure the whole journal, the status watcher's log and the console are kept here.
LOGS=${THRUSTERD_CI_LOGS:-/tmp/thrusterd-systemd-test-logs}
fail() {
    echo "FAIL: $*" >&2
    if [ -n "${LEADER:-}" ]; then
        rm -rf "$LOGS" && mkdir -p "$LOGS"
        inside 'journalctl --no-pager -o short-precise' >"$LOGS/journal.txt" 2>&1 || true
        inside 'cat /tmp/imu-watch.log' >"$LOGS/imu-watch.log" 2>&1 || true
        cp "$WORK/console.log" "$LOGS/" 2>/dev/null || true
        echo "--- journal of both units (last 60 lines; all of it in $LOGS) ---" >&2
        inside 'journalctl --no-pager -o short-precise -n 60 -u thrusterd -u thruster-hw -u thruster-bridge' >&2 || true
    fi
    exit 1
}

[ "$(id -u)" = 0 ] || fail "setup: must run as root (systemd-nspawn, overlay mount)"

# --- host tools (idempotent: apt only when something is missing) -----------------------------
if ! command -v systemd-nspawn >/dev/null || ! command -v mmdebstrap >/dev/null; then
    echo "installing systemd-container and mmdebstrap"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        systemd-container mmdebstrap >/dev/null || fail "setup: apt-get install"
fi

# --- rootfs, once ----------------------------------------------------------------------------
if [ ! -x "$ROOTFS/lib/systemd/systemd" ]; then
    say "building the container rootfs in $ROOTFS (once, about 30 s to 2 min)"
    mkdir -p "$CACHE"
    rm -rf "$ROOTFS.tmp"
    mmdebstrap --quiet --variant=minbase --include="$PACKAGES" bookworm "$ROOTFS.tmp" \
        || fail "setup: mmdebstrap"
    mv "$ROOTFS.tmp" "$ROOTFS"
fi

# --- binaries (debug: quick to build, the same code) -----------------------------------------
say "cargo build --bins"
(cd "$REPO" && cargo build --quiet --bins) || fail "setup: cargo build --bins"
TARGET=$(cd "$REPO" && cargo metadata --format-version 1 --no-deps \
    | sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')
BIN=$TARGET/debug

# --- the container: an overlay, so the cached rootfs stays clean -----------------------------
WORK=$(mktemp -d /tmp/thrusterd-systemd-test.XXXXXX)
MNT=$WORK/root
mkdir -p "$WORK/upper" "$WORK/work" "$MNT"
NSPAWN_PID=
LEADER=
cleanup() {
    local rc=$?
    set +e
    if [ -n "$NSPAWN_PID" ] && kill -0 "$NSPAWN_PID" 2>/dev/null; then
        # SIGTERM: nspawn asks the container's systemd to power off.
        kill -TERM "$NSPAWN_PID"
        for _ in $(seq 50); do kill -0 "$NSPAWN_PID" 2>/dev/null || break; sleep 0.2; done
        kill -0 "$NSPAWN_PID" 2>/dev/null && kill -KILL "$NSPAWN_PID"
        wait "$NSPAWN_PID" 2>/dev/null
    fi
    mountpoint -q "$MNT" && umount "$MNT"
    rm -rf "$WORK"
    say "exit $rc, wall time $(elapsed) s"
    exit $rc
}
trap cleanup EXIT
mount -t overlay overlay -o "lowerdir=$ROOTFS,upperdir=$WORK/upper,workdir=$WORK/work" "$MNT" \
    || fail "setup: overlay mount"

# What the README's install commands expect in their working directory.
SRC=$MNT/root/thrusterd-src
mkdir -p "$SRC/target/release"
cp -r "$REPO/config" "$SRC/"
cp "$BIN"/thrusterd "$BIN"/thrusterctl "$BIN"/thruster-hw "$BIN"/thruster-sim "$BIN"/thruster-bridge \
    "$SRC/target/release/"

say "booting systemd in the container"
# Facts from issue 13: no host systemd/D-Bus (--register=no --keep-unit), a mixed cgroup layout
# (unified hierarchy forced), bpf() for IPAddressDeny=, a read-only console (a passive one can
# block PID 1).
SYSTEMD_NSPAWN_UNIFIED_HIERARCHY=1 systemd-nspawn --quiet --boot --directory="$MNT" \
    --machine="thrusterd-ci-$$" --register=no --keep-unit --console=read-only \
    --capability=CAP_BPF,CAP_NET_ADMIN --system-call-filter=bpf \
    >"$WORK/console.log" 2>&1 &
NSPAWN_PID=$!

# The container's PID 1: the descendant of nspawn that is PID 1 in its own namespace.
for _ in $(seq 100); do
    for p in $(pgrep -P "$NSPAWN_PID" 2>/dev/null) $(for c in $(pgrep -P "$NSPAWN_PID"); do pgrep -P "$c"; done); do
        if [ "$(awk '/^NSpid:/ {print $NF}' "/proc/$p/status" 2>/dev/null)" = 1 ]; then LEADER=$p; fi
    done
    [ -n "$LEADER" ] && break
    kill -0 "$NSPAWN_PID" 2>/dev/null || { cat "$WORK/console.log"; fail "boot: nspawn exited"; }
    sleep 0.1
done
[ -n "$LEADER" ] || fail "boot: no container PID 1 after 10 s"

inside() {
    nsenter -t "$LEADER" -a -- /usr/bin/env -i \
        PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LANG=C.UTF-8 \
        /bin/bash -c "$1"
}
for _ in $(seq 150); do
    state=$(inside 'systemctl is-system-running' 2>/dev/null || true)
    case "$state" in running | degraded) break ;; esac
    sleep 0.2
done
case "$state" in running | degraded) ;; *) fail "boot: system state '$state' after 30 s" ;; esac
say "systemd up ($state)"


prop() { inside "systemctl show -P $2 $1"; }
# journal_says IDENTIFIER PATTERN [SINCE]: the journal has a line of that program matching
# PATTERN (since SINCE, a "date +%s.%N" inside the container, if given) within 5 s. By
# identifier, not -u: journald attributes a line to a unit through /proc/<pid>/cgroup, gone
# when the process has already exited (systemd issue #2913), so the last lines of a process
# that exits (a bad configuration, a summary at stop, ExecStopPost) may lack the unit; the
# identifier comes with the stdout stream itself.
journal_says() {
    inside "for i in 1 2 3 4 5; do journalctl -t $1 ${3:+--since @$3} --no-pager -o cat \
            | grep -q '$2' && exit 0; sleep 1; done; exit 1"
}
as_operator() { inside "runuser -u alice -- thrusterctl --namespace $NS --ipc-root $IPC $1"; }

# --- install exactly as the README says ------------------------------------------------------
# The README's "Install on a vehicle" code blocks, in order; `cargo build` was done above
# (debug binaries placed where the README expects release ones), `sudo` is a no-op for root.
readme_block() {
    awk -v want="$1" '
        /^## Install on a vehicle/ { sec = 1; next }
        /^## / { sec = 0 }
        sec && /^```sh/ { n++; inb = (n == want); next }
        sec && /^```/ { inb = 0; next }
        inb { print }' "$REPO/README.md"
}
INSTALL=$(readme_block 1 | grep -v '^cargo build')
START=$(readme_block 2)
BRIDGE=$(readme_block 3)
[ -n "$INSTALL" ] && [ -n "$START" ] && [ -n "$BRIDGE" ] || fail "install: README install section not found"
inside "sudo() { \"\$@\"; }; set -e; cd /root/thrusterd-src; $INSTALL" \
    || fail "install: the README's install commands failed"

# The README's edit step: one namespace and the shared ipc root in both files. The shipped
# files already share the namespace (checked, not edited into agreement).
inside "set -e
    grep -q '^namespace = \"$NS\"' /etc/thrusterd/thrusterd.toml
    grep -q '^namespace = \"$NS\"' /etc/thrusterd/thruster-hw.toml
    sed -i 's|^# root = \"/run/thrusterd\"|root = \"$IPC\"|' /etc/thrusterd/thrusterd.toml
    grep -q '^root = \"$IPC\"' /etc/thrusterd/thrusterd.toml
    sed -i 's|^namespace = .*|namespace = \"$NS\"|; s|^ipc_root = .*|ipc_root = \"$IPC\"|' /etc/thrusterd/thruster-hw.toml
    grep -q '^ipc_root = \"$IPC\"' /etc/thrusterd/thruster-hw.toml" \
    || fail "install: editing the configs as the README says (shipped namespace not '$NS'?)"

# The one departure from the shipped thrusterd.toml, for this test bed only: imu_timeout_ms 500
# (shipped: 100). Here the driver is a debug build of the simulator in a container on a shared
# 2-core machine (CI builds run beside it), and it was seen to publish nothing for about 120 ms
# now and then while the daemon was not blocked (its IMU inbox was empty when the deadline
# fired): one estimation in five failed on that. The test checks that the IMU keeps flowing
# (a hang), not the vehicle computer's 100 ms margin; 500 ms is still 4x shorter than the
# watchdog, and a SIGSTOPped driver still faults the daemon.
inside "set -e
    sed -i 's|^imu_timeout_ms = .*|imu_timeout_ms = 500|' /etc/thrusterd/thrusterd.toml
    grep -q '^imu_timeout_ms = 500\$' /etc/thrusterd/thrusterd.toml" \
    || fail "install: imu_timeout_ms of the test bed"

# The unit's ExecStopPost (`thruster-hw neutral`) reads the driver's config; here the unit runs
# the simulator, so that config may name the Linux backend on a stand-in sysfs tree whose
# duties the SIGSTOP check below sets to full thrust, as a killed driver would leave them.
FAKE_SYSFS=/var/lib/thruster-hw-fake-sysfs
inside "set -e
    sed -i 's|^backend = .*|backend = \"linux\"|; s|^sysfs_root = .*|sysfs_root = \"$FAKE_SYSFS\"|' /etc/thrusterd/thruster-hw.toml
    grep -q '^sysfs_root = \"$FAKE_SYSFS\"' /etc/thrusterd/thruster-hw.toml
    for ch in 1 2 3 4 5; do
        install -d $FAKE_SYSFS/class/pwm/pwmchip0/pwm\$ch
        echo 1500000 > $FAKE_SYSFS/class/pwm/pwmchip0/pwm\$ch/duty_cycle
    done
    chown -R thrusterd:thrusterd $FAKE_SYSFS" \
    || fail "install: the stand-in PWM tree for ExecStopPost"

# No vehicle here: thruster-hw.service runs the simulator in real time (a runtime drop-in).
inside "set -e
    install -m 0755 /root/thrusterd-src/target/release/thruster-sim /usr/local/bin/
    install -d /etc/thrusterd/vehicles
    install -m 0644 /root/thrusterd-src/config/vehicles/amour5.toml /etc/thrusterd/vehicles/
    install -m 0644 /root/thrusterd-src/config/thruster-sim.toml /etc/thrusterd/
    sed -i 's|^namespace = .*|namespace = \"$NS\"|; s|^ipc_root = .*|ipc_root = \"$IPC\"|; s|^mode = .*|mode = \"realtime\"|' /etc/thrusterd/thruster-sim.toml
    mkdir -p /run/systemd/system/thruster-hw.service.d
    printf '[Service]\nExecStart=\nExecStart=/usr/local/bin/thruster-sim run --config /etc/thrusterd/thruster-sim.toml\n' \
        > /run/systemd/system/thruster-hw.service.d/sim.conf
    # Test bed only: this sandbox's root has no CAP_SYS_RESOURCE, so the container's systemd
    # cannot raise RLIMIT_RTPRIO and the shipped unit's LimitRTPRIO=50 arrives as 0 (the
    # daemon then logs 'SCHED_FIFO priority 50 refused' and runs at normal priority; seen).
    # CAP_SYS_NICE stands in for the limit here; on a vehicle the limit is enough.
    mkdir -p /run/systemd/system/thrusterd.service.d
    printf '[Service]\nCapabilityBoundingSet=CAP_SYS_NICE\nAmbientCapabilities=CAP_SYS_NICE\n' \
        > /run/systemd/system/thrusterd.service.d/testbed-realtime.conf
    useradd --create-home alice
    useradd --create-home bob" || fail "install: simulator drop-in and test accounts"

say "systemctl enable --now thruster-hw thrusterd (README)"
inside "sudo() { \"\$@\"; }; set -e; ${START//OPERATOR/alice}" \
    || fail "notify start: the README's start commands failed"

status_json() { as_operator "status --json" | tr -d '\n'; }
json_num() { sed -n "s/.*\"$1\": *\([0-9.]*\).*/\1/p"; }
json_str() { sed -n "s/.*\"$1\": *\"\([^\"]*\)\".*/\1/p"; }
now() { echo "$EPOCHREALTIME"; }
imu_good() { # a status that answered with IMU above 150 Hz
    local r
    r=$(echo "$1" | json_num imu_rate_hz)
    [ -n "$r" ] && [ "${r%.*}" -ge 150 ]
}
imu_ok() { # the watcher's status calls that started between FROM and TO (epoch seconds; TO
    # empty: the first 3 that started after FROM, waiting 10 s at most for them) all answered
    # with IMU above 150 Hz. By start time: a call still waiting on a killed daemon ends with a
    # timeout after the restart, and is not a call made after it.
    local bad n
    for _ in $(seq 50); do
        inside "cat /tmp/imu-watch.log" | awk -v a="$1" -v b="${2:-9e99}" '$1 >= a && $1 <= b' \
            | head -n "$([ -n "$2" ] && echo 100000 || echo 3)" >"$WORK/window"
        n=$(wc -l <"$WORK/window")
        [ -n "$2" ] || [ "$n" -ge 3 ] && break
        sleep 0.2
    done
    [ "$n" -ge 2 ] || fail "real-time sim: only $n status samples ($3)"
    bad=$(while read -r l; do imu_good "$l" || echo "$l"; done <"$WORK/window")
    [ -z "$bad" ] || fail "real-time sim: IMU not flowing ($3): $(echo "$bad" | head -3)"
}
wait_imu_back() { # after a restart: until alice's status shows IMU above 150 Hz (10 s at most)
    local st
    for _ in $(seq 40); do
        st=$(status_json 2>/dev/null) && imu_good "$st" && return 0
        sleep 0.25
    done
    fail "real-time sim: no status with IMU above 150 Hz within 10 s ($1)"
}


# --- checks ------------------------------------------------------------------------------------
check_active() { # unit: active, Type=notify, watchdog 2 s
    local s
    s=$(inside "systemctl show -p ActiveState -p SubState -p Type -p WatchdogUSec $1 | sort | tr '\n' ' '")
    [ "$s" = "ActiveState=active SubState=running Type=notify WatchdogUSec=2s " ] \
        || fail "notify start: $1 is '$s', want active/running, Type=notify, WatchdogUSec=2s"
}
check_active thruster-hw
check_active thrusterd
[ "$(inside "stat -c '%U:%G %a' $IPC")" = "thrusterd:thrusterd 2770" ] \
    || fail "ipc root: $IPC is '$(inside "stat -c '%U:%G %a' $IPC")', want thrusterd:thrusterd 2770"
say "notify start: both units active after READY"

# Real-time scheduling (issue 25): the unit's --realtime-priority 50 with LimitRTPRIO=50 puts
# the control thread, and only it, at SCHED_FIFO 50 for the unprivileged user thrusterd; the
# solver, saver, loader and reaper threads stay normal (policy field 41 of /proc/TID/stat:
# 1 = FIFO; rt_priority field 40).
SCHED=$(inside "pid=\$(systemctl show -p MainPID --value thrusterd)
    for t in /proc/\$pid/task/*; do sed 's/.*) //' \$t/stat | awk '{print \$39 \":\" \$38}'; done | sort | uniq -c | tr -s ' ' | tr '\n' ','")
FIFO=$(echo "$SCHED" | tr ',' '\n' | awk '$2 == "1:50" {print $1}')
OTHER=$(echo "$SCHED" | tr ',' '\n' | awk '$2 == "0:0" {n += $1} END {print n + 0}')
[ "$FIFO" = 1 ] && [ "$OTHER" -ge 3 ] && [ "$(echo "$SCHED" | tr ',' '\n' | grep -c .)" = 2 ] \
    || fail "real-time: thrusterd's threads (count policy:priority) are '$SCHED', want one at 1:50 (SCHED_FIFO 50) and the rest 0:0; its cpu cgroup: $(inside 'grep -E ":cpu[,:]" /proc/$(systemctl show -p MainPID --value thrusterd)/cgroup' | tr '\n' ' '); its limit: $(inside 'grep -i realtime /proc/$(systemctl show -p MainPID --value thrusterd)/limits; grep -i realtime /proc/1/limits')"
say "real-time: the control thread at SCHED_FIFO 50, $OTHER other threads normal ($SCHED)"

# IMU must flow the whole run (a real-time sim that hangs starves the daemon): a watcher
# inside the container samples the daemon's status every 0.5 s into a file, until
# /tmp/imu-watch.stop exists (the minimal rootfs has no pkill).
# Each line: the call's start time (epoch s), then its output.
cat >"$MNT/usr/local/bin/imu-watch" <<WATCH
#!/bin/bash
while [ ! -e /tmp/imu-watch.stop ] && sleep 0.5; do
    t=\$(date +%s.%N)
    echo "\$t \$(thrusterctl --namespace $NS --ipc-root $IPC status --json 2>&1 | tr -d '\\n')"
done
WATCH
chmod 0755 "$MNT/usr/local/bin/imu-watch"
WATCHER=$(inside "nohup runuser -u alice -- imu-watch </dev/null >/tmp/imu-watch.log 2>&1 & echo \$!")
T_WATCH=$(now)

# Operator account in group thrusterd.
st=$(status_json) || fail "operator: thrusterctl status as alice (group thrusterd) failed: $st"
say "operator: alice's status works: state $(echo "$st" | json_str state)"
# The README's configs and the simulator drop-in agree: the daemon hears thruster-sim on the
# shared namespace with the 5 thrusters of amour5 and of thrusterd.toml (a count mismatch
# would fault it, neutral).
drv=$(echo "$st" | json_str driver); cnt=$(echo "$st" | json_num thruster_count)
[ "$drv" = thruster-sim ] && [ "$cnt" = 5 ] \
    || fail "configs: the daemon's driver is '$drv' with '$cnt' thrusters, want thruster-sim with 5: $st"
[ "$(echo "$st" | json_str state)" != Fault ] || fail "configs: the daemon is in Fault at start: $st"

# Watchdog over a whole estimation.
NR_D=$(prop thrusterd NRestarts); PID_D=$(prop thrusterd MainPID)
NR_H=$(prop thruster-hw NRestarts)
# In real time the daemon may refuse a model honestly (a late sample on a loaded machine can
# put the lag's row groups apart: "model rejected; old model kept", exit 4 "without a new
# model"); the operator asks again, as the emergency-stop and bridge tests do, at most three
# times. The watchdog is checked over every attempt.
for attempt in 1 2 3; do
    if as_operator "estimate --wait --max-wait-s 90" >"$WORK/estimate.log" 2>&1; then break; fi
    grep -q 'without a new model' "$WORK/estimate.log" && [ "$attempt" -lt 3 ] \
        || { cat "$WORK/estimate.log"; fail "estimation: thrusterctl estimate --wait failed (attempt $attempt)"; }
    say "estimation $attempt refused, asking again: $(tail -1 "$WORK/estimate.log")"
done
[ "$(prop thrusterd NRestarts)" = "$NR_D" ] && [ "$(prop thrusterd MainPID)" = "$PID_D" ] \
    || fail "watchdog: thrusterd restarted during the estimation"
[ "$(prop thruster-hw NRestarts)" = "$NR_H" ] || fail "watchdog: thruster-hw restarted during the estimation"
inside "journalctl -u thrusterd -u thruster-hw --no-pager | grep -q 'Watchdog timeout'" \
    && fail "watchdog: a watchdog timeout was logged during the estimation"
MODEL=$(status_json | json_num model_version)
[ -n "$MODEL" ] && [ "$MODEL" -ge 1 ] || fail "estimation: no model after estimate --wait"
inside "ls /var/lib/thrusterd/*" >/dev/null || fail "estimation: nothing saved in /var/lib/thrusterd"
say "watchdog: fed over a whole estimation (model version $MODEL, no restart)"

# root (sudo thrusterctl) and a non-member are refused before any file; the daemon is unharmed.
for who in root bob; do
    if [ $who = root ]; then cmd="thrusterctl --namespace $NS --ipc-root $IPC status"
    else cmd="runuser -u bob -- thrusterctl --namespace $NS --ipc-root $IPC status"; fi
    set +e; out=$(inside "$cmd" 2>&1); code=$?; set -e
    [ $code = 7 ] || fail "refusal: thrusterctl as $who exited $code, want 7: $out"
    echo "$out" | grep -q "$IPC" && echo "$out" | grep -q "usermod -aG thrusterd" \
        || fail "refusal: message for $who names neither $IPC nor the fix: $out"
done
# Access (issue 25): bob, outside the group, can open none of the namespace's files (as root
# lists them: /dev/shm/thr_NS_* and everything under the ipc root) and cannot publish a
# setpoint with a raw iceoryx2 publisher (no thrusterctl, no check_access). alice, a member,
# runs the same probe as the control: it must find files it can open and publish.
cp "$BIN/ipc-intruder" "$MNT/usr/local/bin/"
inside "(ls -d /dev/shm/thr_${NS}_* ; find $IPC) >/tmp/ipc-paths; chmod 0644 /tmp/ipc-paths"
npaths=$(inside "wc -l </tmp/ipc-paths")
intrude() { inside "runuser -u $1 -- ipc-intruder --namespace $NS --ipc-root $IPC --paths-from /tmp/ipc-paths ${2:-} 2>/tmp/intruder-$1.err"; }
out=$(intrude bob) || fail "access: ipc-intruder as bob did not run: $out $(inside 'cat /tmp/intruder-bob.err')"
echo "$out" | grep -Eq '"readable":0[,}]' && echo "$out" | grep -Eq '"writable":0[,}]' \
    && echo "$out" | grep -q '"published":false' \
    || fail "access: bob (outside the group) reached the vehicle's IPC: $out"
ctl=$(intrude alice "--pitch-deg 0") || fail "access: ipc-intruder as alice did not run: $ctl $(inside 'cat /tmp/intruder-alice.err')"
echo "$ctl" | grep -q '"published":true' && ! echo "$ctl" | grep -Eq '"readable":0[,}]' \
    || fail "access: the probe found nothing alice (group member) may open; it would miss a leak: $ctl"
say "access: bob opened 0 of $npaths IPC files for reading or writing and could not publish ($(echo "$out" | sed 's/.*"error":"//; s/","paths".*//' | cut -c1-100)); alice, a member, could (control)"
inside "find $IPC /dev/shm -mindepth 1 \\( -user root -o -user bob \\) -print" >"$WORK/foreign"
[ ! -s "$WORK/foreign" ] || fail "refusal: files of root/bob appeared: $(head -3 "$WORK/foreign")"
sleep 3
[ "$(prop thrusterd NRestarts)" = "$NR_D" ] && [ "$(prop thrusterd MainPID)" = "$PID_D" ] \
    || fail "refusal: thrusterd restarted after a refused client"
st=$(status_json) || fail "refusal: the daemon stopped answering alice"
say "refusal: root and bob exit 7 with the fix named, no file made, daemon unharmed"

# The bridge (README's third block): Type=notify, READY once it listens on the shipped config's
# loopback address; a TCP connection reaches it (bash's /dev/tcp: the rootfs has no client);
# the daemon keeps running untouched.
inside "sudo() { \"\$@\"; }; set -e; $BRIDGE" || fail "bridge: the README's bridge commands failed"
s=$(inside "systemctl show -p ActiveState -p SubState -p Type thruster-bridge | sort | tr '\n' ' '")
[ "$s" = "ActiveState=active SubState=running Type=notify " ] \
    || fail "bridge: thruster-bridge is '$s', want active/running, Type=notify"
inside "journalctl -u thruster-bridge --no-pager -o cat | grep -q 'live view on ws://127.0.0.1:8765'" \
    || fail "bridge: no 'live view on ws://127.0.0.1:8765' in its journal"
inside "exec 3<>/dev/tcp/127.0.0.1/8765" || fail "bridge: no TCP connection to 127.0.0.1:8765"
[ "$(prop thrusterd NRestarts)" = "$NR_D" ] && [ "$(prop thrusterd MainPID)" = "$PID_D" ] \
    || fail "bridge: thrusterd restarted when the bridge started"
say "bridge: active after READY, listening on 127.0.0.1:8765, daemon untouched"

imu_ok "$T_WATCH" "$(now)" "from the start to the daemon's kill"

# kill -9 -> restart -> resume with the saved model.
inside "kill -9 $PID_D"
for _ in $(seq 100); do
    pid=$(prop thrusterd MainPID); act=$(prop thrusterd ActiveState)
    [ "$pid" != "$PID_D" ] && [ "$pid" != 0 ] && [ "$act" = active ] && break
    sleep 0.1
done
[ "$(prop thrusterd NRestarts)" = $((NR_D + 1)) ] || fail "kill -9: thrusterd not restarted once (NRestarts $(prop thrusterd NRestarts))"
sleep 0.5
log=$(inside "journalctl _SYSTEMD_INVOCATION_ID=$(prop thrusterd InvocationID) --no-pager -o cat")
echo "$log" | grep -q 'loaded the saved model' \
    || fail "kill -9: the restarted daemon did not load the saved model: $log"
echo "$log" | grep -q 'resuming control with the saved model' \
    || fail "kill -9: the restarted daemon did not resume control: $log"
st=$(status_json) || fail "kill -9: the restarted daemon does not answer"
v=$(echo "$st" | json_num model_version)
[ -n "$v" ] && [ "$v" -ge 1 ] || fail "kill -9: no model in force after the restart: $st"
PID_D=$(prop thrusterd MainPID); NR_D=$(prop thrusterd NRestarts)
wait_imu_back "after the daemon's restart"
imu_ok "$(now)" "" "after the daemon's restart"
say "kill -9: restarted, saved model loaded, control resumed, IMU flows"

# The driver's watchdog: a stopped (hung) driver is killed and restarted by systemd, and its
# ExecStopPost leaves the outputs neutral (the stand-in tree at full thrust before).
PID_H=$(prop thruster-hw MainPID)
inside "for ch in 1 2 3 4 5; do echo 1900000 > $FAKE_SYSFS/class/pwm/pwmchip0/pwm\$ch/duty_cycle; done"
inside "kill -STOP $PID_H"
for _ in $(seq 150); do
    pid=$(prop thruster-hw MainPID)
    [ "$pid" != "$PID_H" ] && [ "$pid" != 0 ] && [ "$(prop thruster-hw ActiveState)" = active ] && break
    sleep 0.1
done
[ "$(prop thruster-hw NRestarts)" = $((NR_H + 1)) ] \
    || fail "driver watchdog: SIGSTOPped thruster-hw not restarted within 15 s (NRestarts $(prop thruster-hw NRestarts))"
inside "journalctl -u thruster-hw --no-pager | grep -q 'Watchdog timeout'" \
    || fail "driver watchdog: no 'Watchdog timeout' for thruster-hw in the journal"
duties=$(inside "cat $FAKE_SYSFS/class/pwm/pwmchip0/pwm*/duty_cycle | sort -u")
[ "$duties" = 1500000 ] || fail "driver watchdog: ExecStopPost left the duties at $duties, not neutral"
journal_says thruster-hw 'pwm5: neutral (1500 us)' \
    || fail "driver watchdog: no 'pwm5: neutral' from ExecStopPost in the journal"
wait_imu_back "after the driver's restart"
imu_ok "$(now)" "" "after the driver's restart"
[ "$(prop thrusterd NRestarts)" = "$NR_D" ] || fail "driver watchdog: thrusterd restarted too"
say "driver watchdog: a stopped thruster-hw was killed, its outputs left neutral (ExecStopPost), restarted, IMU flows again"

# The watcher ends before the stop (a status call then would only time out).
inside "touch /tmp/imu-watch.stop; for _ in \$(seq 30); do kill -0 $WATCHER 2>/dev/null || exit 0; sleep 0.1; done; exit 1" \
    || fail "setup: the status watcher did not end within 3 s"

# No leaks (issue 25): 100 operator calls leave /dev/shm and the ipc root as they were, and a
# client killed with -9 leaves nothing after the daemon's next dead-node search (every 2 s).
ipc_usage() { inside "set -e; n=\$(ls /dev/shm | grep -c '^thr_${NS}_' || true)
    b=\$(cat /dev/shm/thr_${NS}_* 2>/dev/null | wc -c)
    rn=\$(find $IPC | wc -l); rb=\$(find $IPC -type f -printf '%s\\n' | awk '{s += \$1} END {print s + 0}')
    echo \"\$n files \$((b / 1024)) KiB in /dev/shm, \$rn entries \$((rb / 1024)) KiB under $IPC\""; }
sleep 1
before=$(ipc_usage)
inside "for i in \$(seq 100); do runuser -u alice -- thrusterctl --namespace $NS --ipc-root $IPC status >/dev/null || exit 1; done" \
    || fail "leaks: an operator status call failed"
sleep 1
after=$(ipc_usage)
say "leaks: 100 operator status calls: before $before; after $after"
[ "$before" = "$after" ] || fail "leaks: 100 status calls changed the namespace's files: before $before, after $after"
# setpriv execs (runuser forks), so $! is thrusterctl itself.
KILLED=$(inside "nohup setpriv --reuid alice --regid alice --init-groups thrusterctl --namespace $NS --ipc-root $IPC watch </dev/null >/dev/null 2>&1 & echo \$!")
sleep 2
during=$(ipc_usage)
[ "$during" != "$before" ] || fail "leaks: a running watch made no files; the check would miss a leak"
inside "kill -9 $KILLED" || fail "leaks: could not kill the watch (pid $KILLED)"
for _ in $(seq 40); do [ "$(ipc_usage)" = "$before" ] && break; sleep 0.25; done
[ "$(ipc_usage)" = "$before" ] \
    || fail "leaks: a watch killed with -9 left files 10 s later: before $before, now $(ipc_usage)"
say "leaks: a watch killed with -9 ($during while it ran) left nothing once the daemon searched for dead nodes"

# A stalled journald never stalls control (issue 25): journald stopped (SIGSTOP), the daemon's
# control thread logs more warnings than the kernel queues for it (an operator's refused
# `abort`, one warning each), and every call is still answered at once (exit 4, refused; 0 for
# a first one that found something to abort), the daemon not restarted, the IMU flowing. With the published tracing-journald the call after
# the queue filled blocked the control thread: the calls timed out (exit 5) until systemd's
# watchdog restarted the daemon.
QLEN=$(inside "cat /proc/sys/net/unix/max_dgram_qlen")
CALLS=$((QLEN + 20))
PID_D=$(prop thrusterd MainPID); NR_D=$(prop thrusterd NRestarts)
JCONT="systemctl kill --signal=SIGCONT systemd-journald"
inside "systemctl kill --signal=SIGSTOP systemd-journald" || fail "journald: could not stop systemd-journald"
t_stall=$(now)
# setpriv, not runuser: runuser's PAM session logs to the stalled journald itself.
codes=$(inside "for i in \$(seq $CALLS); do setpriv --reuid alice --regid alice --init-groups thrusterctl --namespace $NS --ipc-root $IPC abort >/dev/null 2>&1; echo \$?; done" | sort | uniq -c | tr -s ' \n' ' ')
stalled_s=$(awk -v a="$t_stall" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }')
st=$(inside "setpriv --reuid alice --regid alice --init-groups thrusterctl --namespace $NS --ipc-root $IPC status --json" | tr -d '\n') \
    || { inside "$JCONT"; fail "journald stalled: the daemon did not answer status: $st"; }
pid_after=$(prop thrusterd MainPID); nr_after=$(prop thrusterd NRestarts)
inside "$JCONT"
# Answered means exit 4 (refused) or 0 (the first may find something to abort); 5 is a
# timeout: the control thread did not answer.
unanswered=$(echo "$codes" | awk '{ for (i = 1; i < NF; i += 2) if ($(i + 1) != 0 && $(i + 1) != 4) n += $i } END { print n + 0 }')
[ "$unanswered" = 0 ] \
    || fail "journald stalled: $unanswered of $CALLS calls not answered (count code: $codes) in ${stalled_s} s"
[ "$pid_after" = "$PID_D" ] && [ "$nr_after" = "$NR_D" ] \
    || fail "journald stalled: thrusterd restarted (pid $PID_D -> $pid_after, NRestarts $NR_D -> $nr_after)"
imu_good "$st" || fail "journald stalled: status without the IMU above 150 Hz: $st"
sleep 1
say "journald stalled ${stalled_s} s (queue of $QLEN): $CALLS abort calls (count code:$codes), each refusal a warning on the control thread, all answered, no restart, IMU flowing"

# The bridge stops cleanly (SIGTERM: server closed, summary logged).
inside "systemctl stop thruster-bridge"
[ "$(prop thruster-bridge Result)" = success ] \
    || fail "bridge: stopped with $(prop thruster-bridge Result)"
journal_says thruster-bridge 'live view logged' \
    || fail "bridge: no summary in its journal at stop"

# A configuration that cannot be used: exit 2, and RestartPreventExitStatus=2 keeps systemd
# from restarting it (RestartSec=1: three seconds would be three restarts).
NR_B=$(prop thruster-bridge NRestarts)
inside "cp /etc/thrusterd/thruster-bridge.toml /etc/thrusterd/thruster-bridge.toml.good \
    && echo 'bogus_key = 1' >> /etc/thrusterd/thruster-bridge.toml"
inside "systemctl start thruster-bridge" 2>/dev/null && fail "bad config: the bridge's start succeeded"
sleep 3
bad="$(prop thruster-bridge ActiveState) $(prop thruster-bridge Result) $(prop thruster-bridge ExecMainStatus) $(prop thruster-bridge NRestarts)"
[ "$bad" = "failed exit-code 2 $NR_B" ] \
    || fail "bad config: the bridge is '$bad', want 'failed exit-code 2 $NR_B' (state result status restarts)"
journal_says thruster-bridge 'unknown field .bogus_key.' \
    || fail "bad config: the journal does not name the unknown key"
# And `systemctl status` says why without the journal: STATUS= sent behind a barrier before
# the exit (driver-kit `report_failure`), kept by systemd until the unit's next start.
st=$(prop thruster-bridge StatusText)
echo "$st" | grep -q '^failed: .*unknown field .bogus_key.' \
    || fail "bad config: the unit's status text is '$st', not the reason"
inside "mv /etc/thrusterd/thruster-bridge.toml.good /etc/thrusterd/thruster-bridge.toml && systemctl reset-failed thruster-bridge"
say "bad config: the bridge exits 2 naming the key in the journal and its status text ($st), failed at once, not restarted"

# systemctl stop -> neutral and model saved.
T_STOP=$(inside "date +%s.%N")
inside "systemctl stop thrusterd"
[ "$(prop thrusterd ActiveState)" = inactive ] && [ "$(prop thrusterd Result)" = success ] \
    || fail "stop: thrusterd is $(prop thrusterd ActiveState)/$(prop thrusterd Result) after stop"
journal_says thrusterd 'shutting down: thrusters neutral' "$T_STOP" || fail "stop: no neutral shutdown in the log"
journal_says thrusterd 'model saved' "$T_STOP" || fail "stop: the model was not saved at stop"
inside "systemctl stop thruster-hw"
[ "$(prop thruster-hw Result)" = success ] || fail "stop: thruster-hw stopped with $(prop thruster-hw Result)"
say "stop: thrusters neutral, model saved, both units stopped cleanly"

# The daemon's own bad configuration: exit 2, not restarted, and the reason in the unit's
# status text (thrusterd's main reports it as the drivers' driver_main does).
inside "cp /etc/thrusterd/thrusterd.toml /etc/thrusterd/thrusterd.toml.good \
    && echo 'bogus_daemon_key = 1' >> /etc/thrusterd/thrusterd.toml"
inside "systemctl start thrusterd" 2>/dev/null && fail "bad daemon config: thrusterd's start succeeded"
sleep 2
bad="$(prop thrusterd ActiveState) $(prop thrusterd Result) $(prop thrusterd ExecMainStatus)"
[ "$bad" = "failed exit-code 2" ] || fail "bad daemon config: thrusterd is '$bad', want 'failed exit-code 2'"
st=$(prop thrusterd StatusText)
echo "$st" | grep -q '^failed: .*bogus_daemon_key' \
    || fail "bad daemon config: thrusterd's status text is '$st', not the reason"
inside "mv /etc/thrusterd/thrusterd.toml.good /etc/thrusterd/thrusterd.toml && systemctl reset-failed thrusterd"
say "bad daemon config: thrusterd exits 2, its status text says why ($st)"
say "all checks passed"
