#!/usr/bin/env bash
# Build a local Python 3.11 base image from Debian packages, for machines that cannot pull
# `python:3.11-slim` from a registry (no registry reachable; see docs/deployment.md).
#
#   deploy/build-base-image.sh [IMAGE_NAME]      # default: quadloc-base:bookworm
#   docker build --network host --build-arg BASE=quadloc-base:bookworm -t quadloc .
#
# debootstrap (minbase variant) installs Debian bookworm's python3 (3.11) + python3-venv + the CA
# certificates; the host's CA bundle is copied in so that pip inside `docker build` trusts the
# same package proxy as the host's pip. The rootfs is imported with `docker import` (one layer,
# about 130 MB). Needs root, debootstrap and a running Docker engine; takes about a minute.
set -euo pipefail
NAME="${1:-quadloc-base:bookworm}"
SUITE="${DEBIAN_SUITE:-bookworm}"
MIRROR="${DEBIAN_MIRROR:-http://deb.debian.org/debian}"
command -v debootstrap >/dev/null || { echo "debootstrap not installed (apt-get install debootstrap)" >&2; exit 2; }
docker info >/dev/null 2>&1 || { echo "no Docker engine reachable (docker info failed)" >&2; exit 2; }
ROOTFS="$(mktemp -d /tmp/quadloc-rootfs.XXXXXX)"
trap 'rm -rf "$ROOTFS"' EXIT
debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates \
    "$SUITE" "$ROOTFS" "$MIRROR" >"$ROOTFS.log" 2>&1 \
    || { tail -n 30 "$ROOTFS.log" >&2; exit 1; }
rm -f "$ROOTFS.log"
# The host's CA bundle: pip in the build container goes through the same package proxy.
if [ -f /etc/ssl/certs/ca-certificates.crt ]; then
    cp /etc/ssl/certs/ca-certificates.crt "$ROOTFS/etc/ssl/certs/ca-certificates.crt"
fi
# Slim down: package caches, docs, man pages, locales (the runtime is C.UTF-8).
rm -rf "$ROOTFS"/var/cache/apt/archives/*.deb "$ROOTFS"/var/lib/apt/lists/* \
       "$ROOTFS"/usr/share/doc/* "$ROOTFS"/usr/share/man/* "$ROOTFS"/usr/share/info/* \
       "$ROOTFS"/usr/share/locale/* "$ROOTFS"/var/log/*.log
tar --numeric-owner -C "$ROOTFS" -c . | docker import \
    --change 'ENV LANG=C.UTF-8' \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'CMD ["python3"]' \
    - "$NAME" >/dev/null
echo "$NAME: $(docker image inspect -f '{{.Size}}' "$NAME" | awk '{printf "%.0f MB", $1/1e6}')"
