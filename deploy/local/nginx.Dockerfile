# Stand-in for nginx:1.27-alpine where no registry is reachable (deploy/compose-local.sh):
# Debian bookworm's nginx-light on the local base; docker-compose.yml mounts deploy/nginx.conf
# as /etc/nginx/nginx.conf, as with the official image.
ARG BASE=quadloc-base:bookworm
FROM ${BASE}
# hadolint ignore=DL3008
RUN apt-get update \
    && apt-get install -y --no-install-recommends nginx-light \
    && rm -rf /var/lib/apt/lists/*
EXPOSE 8080
CMD ["nginx", "-g", "daemon off;"]
