# QuadLoc relocalization service: one Uvicorn process per container (scale with replicas).
#
#   docker build -t quadloc .
#   docker run -p 8000:8000 -v quadloc-data:/data -e QUADLOC_API_KEYS="<sha256hex>:read+write" quadloc
#
# The server refuses to listen on 0.0.0.0 without API keys: set QUADLOC_API_KEYS to the sha256
# hex digest(s) of your key(s) with their scopes (see docs/deployment.md). Maps live in SQLite
# under the /data volume, or in PostgreSQL with QUADLOC_DATABASE_URL=postgresql://user:pw@host/db.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

# Unprivileged runtime user with a fixed uid/gid (volume permissions are predictable).
RUN groupadd --system --gid 10001 quadloc \
    && useradd --system --uid 10001 --gid quadloc --home-dir /home/quadloc --create-home \
       --shell /usr/sbin/nologin quadloc \
    && mkdir -p /data \
    && chown quadloc:quadloc /data

WORKDIR /app
COPY pyproject.toml README.md ./
COPY factors/ factors/
COPY maps/ maps/
COPY service/ service/
COPY sdk/ sdk/

# The README's install (`make serve` -> Makefile target `install`), run with the image's Python:
# the same pip commands, minus the `-e` and the `[dev]` extra that only tests need. The light SDK
# distribution (sdk/) goes first: the server distribution depends on it.
# hadolint ignore=DL3013
RUN python -m pip install --upgrade pip \
    && python -m pip install ./sdk \
    && python -m pip install .

USER 10001:10001
ENV QUADLOC_DATA_DIR=/data \
    QUADLOC_PORT=8000 \
    QUADLOC_WORKERS=1
VOLUME ["/data"]
EXPOSE 8000

# Liveness: /healthz answers 200 while the process serves requests (no curl in slim images).
HEALTHCHECK --interval=15s --timeout=5s --start-period=30s --retries=3 \
    CMD ["python", "-c", "import os, sys, urllib.request; port = os.environ.get('QUADLOC_PORT', '8000'); sys.exit(0 if urllib.request.urlopen(f'http://127.0.0.1:{port}/healthz', timeout=4).status == 200 else 1)"]

# One Uvicorn process per container; settings come from QUADLOC_* variables.
CMD ["quadloc", "serve", "--host", "0.0.0.0"]
