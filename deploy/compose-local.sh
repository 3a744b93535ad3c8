#!/usr/bin/env bash
# Run docker-compose.yml (PostgreSQL + two QuadLoc replicas + nginx + build workers, on a compose
# bridge network)
# where no registry is reachable: local stand-ins for the three images, built from Debian
# packages on the local base (deploy/build-base-image.sh), then `docker-compose up`.
#
#   deploy/compose-local.sh up      # build what is missing, start, wait until nginx answers
#   deploy/compose-local.sh down    # stop and remove the stack and its volumes
#   deploy/compose-local.sh compose logs proxy   # any compose command on the project
#
# Environment: QUADLOC_API_KEYS (required by `up` and `compose`, as for docker-compose.yml;
# `down` works without it), QUADLOC_PROXY_PORT
# (default 8080), QUADLOC_WORKER_REPLICAS (build workers, default 2), QUADLOC_COMPOSE_PROJECT (default quadloc). Works with Debian's docker-compose
# 1.29 (v1) or `docker compose` (v2).
set -euo pipefail
cd "$(dirname "$0")/.."
BASE="${QUADLOC_BASE_IMAGE:-quadloc-base:bookworm}"
export QUADLOC_BASE_IMAGE="$BASE"
export QUADLOC_POSTGRES_IMAGE="${QUADLOC_POSTGRES_IMAGE:-quadloc-local/postgres:15}"
export QUADLOC_NGINX_IMAGE="${QUADLOC_NGINX_IMAGE:-quadloc-local/nginx:1.22}"
PROJECT="${QUADLOC_COMPOSE_PROJECT:-quadloc}"
PORT="${QUADLOC_PROXY_PORT:-8080}"
if command -v docker-compose >/dev/null 2>&1; then COMPOSE=(docker-compose);
elif docker compose version >/dev/null 2>&1; then COMPOSE=(docker compose);
else echo "compose-local: neither docker-compose nor docker compose is installed" >&2; exit 2; fi
COMPOSE+=(-p "$PROJECT" -f docker-compose.yml)

image_missing() { ! docker image inspect "$1" >/dev/null 2>&1; }

case "${1:-}" in
up)
    image_missing "$BASE" && bash deploy/build-base-image.sh "$BASE"
    image_missing "$QUADLOC_POSTGRES_IMAGE" && docker build -q --network host \
        --build-arg BASE="$BASE" -f deploy/local/postgres.Dockerfile -t "$QUADLOC_POSTGRES_IMAGE" deploy/local
    image_missing "$QUADLOC_NGINX_IMAGE" && docker build -q --network host \
        --build-arg BASE="$BASE" -f deploy/local/nginx.Dockerfile -t "$QUADLOC_NGINX_IMAGE" deploy/local
    # The replicas' image: built here (pip needs the host's network during the build).
    docker build -q --network host --build-arg BASE="$BASE" -t quadloc:latest . >/dev/null
    # (--scale: Debian's docker-compose 1.29 ignores the file's deploy.replicas)
    "${COMPOSE[@]}" up -d --no-build --scale worker="${QUADLOC_WORKER_REPLICAS:-2}"
    for _ in $(seq 1 120); do
        if python3 -c "import urllib.request, sys; sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:$PORT/nginx-health', timeout=2).status == 200 else 1)" 2>/dev/null; then
            echo "compose-local: stack up, nginx on 127.0.0.1:$PORT"; exit 0
        fi
        sleep 0.5
    done
    "${COMPOSE[@]}" ps >&2; "${COMPOSE[@]}" logs --tail 20 >&2
    echo "compose-local: nginx did not answer on 127.0.0.1:$PORT within 60 s" >&2; exit 1 ;;
down)  # the keys are not used to stop the stack, but compose refuses the file without them
    QUADLOC_API_KEYS="${QUADLOC_API_KEYS:-unused-by-down}" "${COMPOSE[@]}" down -v --remove-orphans ;;
compose)  # any other compose command on this project, e.g. `compose stop quadloc-1`
    "${COMPOSE[@]}" "${@:2}" ;;
*)
    echo "usage: $0 up|down|compose ARGS..." >&2; exit 2 ;;
esac
