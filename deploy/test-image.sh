#!/usr/bin/env bash
# Build the container image from this checkout and run the image checks against it
# (tests/e2e/test_docker_image.py: non-root, lean, /healthz + /readyz, the demo frame through the
# SDK, API keys enforced / 0.0.0.0 refused without keys, maps surviving a restart on /data,
# SIGTERM stop within 10 s without lost writes, two replicas + PostgreSQL + nginx).
#
#   deploy/test-image.sh                  # starts an engine if it can (deploy/start-docker-engine.sh)
#   QUADLOC_TEST_IMAGE=quadloc:1.2 deploy/test-image.sh     # check an image built elsewhere
#
# Prints the measurements (build time, image size, start-to-ready time, stop time) as JSON.
# Exit status: pytest's (the checks skip, with the reason, when no engine answers).
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/start-docker-engine.sh || true
make --no-print-directory install >/dev/null
report="$(mktemp)"
trap 'rm -f "$report"' EXIT
status=0
QUADLOC_DOCKER_REPORT="$report" .venv/bin/python -m pytest -m docker -v -rs \
    -p no:cacheprovider tests/e2e/test_docker_image.py || status=$?
if [ -s "$report" ]; then echo "image measurements:"; cat "$report"; fi
exit "$status"
