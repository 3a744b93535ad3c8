# QuadLoc relocalization service: one Uvicorn process per container (scale with replicas).
#
#   docker build -t quadloc .
#   docker run -p 8000:8000 -v quadloc-data:/data -e QUADLOC_API_KEYS="<sha256hex>:read+write" quadloc
#
# The server refuses to listen on 0.0.0.0 without API keys: set QUADLOC_API_KEYS to the sha256
# hex digest(s) of your key(s) with their scopes (see docs/deployment.md). Maps live in SQLite
# under the /data volume, or in PostgreSQL with QUADLOC_DATABASE_URL=postgresql://user:pw@host/db.
#
# BASE: any Debian-based image with python3.11 and its venv module. Real deployments use the
# default; where no registry is reachable, deploy/build-base-image.sh builds one from Debian
# packages (then: docker build --network host --build-arg BASE=quadloc-base:bookworm .).
ARG BASE=python:3.11-slim

# ---- build stage: the exact versions of requirements.lock (hash-checked), then the project.
FROM ${BASE} AS build
ENV PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PYTHONDONTWRITEBYTECODE=1
WORKDIR /src
COPY requirements.lock ./
# --no-deps: the lock is the complete list (minus the test tools gtsam declares but never imports).
RUN python3 -m venv /opt/quadloc \
    && /opt/quadloc/bin/python -m pip install --require-hashes --no-deps -r requirements.lock
COPY pyproject.toml README.md ./
COPY factors/ factors/
COPY maps/ maps/
COPY service/ service/
COPY sdk/python/ sdk/python/
# The light SDK distribution (sdk/python/, which the server depends on) and the project from the
# checkout (build backend from the lock); then a smoke test of the imports.
# The numeric kernels (numba, factors/jit.py: the factors', the place search's and the RANSAC
# search's, App.warm_up) are compiled here into their cache (~13 s), so
# that a container starts from it (<1 s); numba needs the directory writable (the runtime user
# owns it; on a read-only file system each process compiles them at start instead). numba
# checks each source file's mtime, which an image layer keeps to the second only: the sources
# get whole-second mtimes before compiling, or every container would compile again; -P: the
# installed package, not the copy in the working directory (numba caches per source path).
ENV NUMBA_CACHE_DIR=/var/cache/quadloc-numba
RUN /opt/quadloc/bin/python -m pip install --no-deps --no-build-isolation ./sdk/python . \
    && /opt/quadloc/bin/python -c "import cv2, gtsam, psycopg, quadloc.service.api.app, quadloc.maps.store" \
    && find /opt/quadloc/lib/python3*/site-packages/quadloc/factors \
       /opt/quadloc/lib/python3*/site-packages/quadloc/service/localization -name "*.py" \
       -exec touch -d "@$(date +%s)" {} + \
    && /opt/quadloc/bin/python -P -c "__import__('quadloc.service.app.context', fromlist=['_']).App.warm_up()" \
    && /opt/quadloc/bin/python -m pip uninstall --yes setuptools wheel

# ---- runtime stage: the base + the venv, no compilers, no test tools, no build backend.
FROM ${BASE}
ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PATH=/opt/quadloc/bin:$PATH \
    NUMBA_CACHE_DIR=/var/cache/quadloc-numba

# Unprivileged runtime user with a fixed uid/gid (volume permissions are predictable).
RUN groupadd --system --gid 10001 quadloc \
    && useradd --system --uid 10001 --gid quadloc --home-dir /home/quadloc --create-home \
       --shell /usr/sbin/nologin quadloc \
    && mkdir -p /data \
    && chown quadloc:quadloc /data

COPY --from=build /opt/quadloc /opt/quadloc
COPY --from=build --chown=10001:10001 /var/cache/quadloc-numba /var/cache/quadloc-numba

USER 10001:10001
WORKDIR /home/quadloc
ENV QUADLOC_DATA_DIR=/data \
    QUADLOC_PORT=8000 \
    QUADLOC_WORKERS=1
VOLUME ["/data"]
EXPOSE 8000

# Liveness: /healthz answers 200 while the process serves requests (no curl in slim images).
HEALTHCHECK --interval=15s --timeout=5s --start-period=30s --retries=3 \
    CMD ["python", "-c", "import os, sys, urllib.request; port = os.environ.get('QUADLOC_PORT', '8000'); sys.exit(0 if urllib.request.urlopen(f'http://127.0.0.1:{port}/healthz', timeout=4).status == 200 else 1)"]

# One Uvicorn process per container; settings come from QUADLOC_* variables. Exec form: the
# server is PID 1 and gets docker stop's SIGTERM (graceful shutdown, docs/deployment.md).
CMD ["quadloc", "serve", "--host", "0.0.0.0"]
