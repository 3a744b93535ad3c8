#!/usr/bin/env bash
# Make a Docker engine answer on this machine, as far as it can be done without a human:
# exit 0 when `docker info` works (already, or after this script started dockerd), 1 otherwise.
#
# On a machine of the development class (Debian bookworm, root, no systemd, no registry):
#   apt-get install docker.io debootstrap (only with QUADLOC_INSTALL_DOCKER=1, or CI=true),
#   then dockerd --iptables=false --ip6tables=false --bridge=none --data-root "$DATA_ROOT" &
# (docs/deployment.md, "On a machine without a registry"). Each step is bounded in time;
# nothing here is fatal for the caller: the image checks skip, with this reason, when no
# engine answers.
set -uo pipefail
DATA_ROOT="${QUADLOC_DOCKER_DATA_ROOT:-/var/lib/docker}"
LOG="${QUADLOC_DOCKER_LOG:-/tmp/quadloc-dockerd.log}"
say() { echo "start-docker-engine: $*" >&2; }

if command -v docker >/dev/null 2>&1 && timeout 20 docker info >/dev/null 2>&1; then
    say "engine already answering"; exit 0
fi
if [ "$(id -u)" != 0 ]; then say "not root: cannot install or start dockerd"; exit 1; fi
if ! command -v dockerd >/dev/null 2>&1; then
    if [ "${QUADLOC_INSTALL_DOCKER:-}" = 1 ] || [ "${CI:-}" = true ]; then
        if command -v apt-get >/dev/null 2>&1; then
            say "installing docker.io debootstrap (apt-get, at most 6 min)"
            export DEBIAN_FRONTEND=noninteractive
            timeout 120 apt-get update -q >/dev/null 2>&1 || say "apt-get update failed"
            timeout 240 apt-get install -y -q -o DPkg::Lock::Timeout=60 docker.io debootstrap \
                >/dev/null 2>&1 || say "apt-get install docker.io failed"
        fi
    fi
    command -v dockerd >/dev/null 2>&1 || { say "dockerd not installed"; exit 1; }
fi
mkdir -p "$DATA_ROOT"
say "starting dockerd (data root $DATA_ROOT, log $LOG)"
nohup dockerd --iptables=false --ip6tables=false --bridge=none --data-root "$DATA_ROOT" \
    >"$LOG" 2>&1 </dev/null &
for _ in $(seq 1 60); do
    if timeout 5 docker info >/dev/null 2>&1; then say "engine up"; exit 0; fi
    sleep 0.5
done
say "dockerd did not answer within 30 s; last log lines:"; tail -n 5 "$LOG" >&2
exit 1
