#!/usr/bin/env bash
# The system tests that need root (they mount small tmpfs disks to fill them): ignored by
# `cargo test --workspace` with that reason, run here. Fails, never skips, without root.
# .ci/run runs this after the README's test command.
set -euo pipefail
cd "$(dirname "$0")/../.."
if [ "$(id -u)" != 0 ]; then
  echo "tests/root/run.sh: needs root (mounts tmpfs disks); run it with sudo" >&2
  exit 1
fi
# --workspace, as the README's test command: with `-p system-tests` cargo resolves features for
# that package alone and rebuilt half the tree (3 min 54 s of CI's 33 min); this way the
# workspace build is reused and only these two test binaries run.
cargo test --workspace --test faults --test recording -- --ignored --exact \
  full_state_disk_when_saving_is_reported_and_the_daemon_keeps_serving \
  a_full_disk_stops_the_recorder_with_file_and_os_error_and_the_daemon_serves_on
