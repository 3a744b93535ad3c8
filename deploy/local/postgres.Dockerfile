# Stand-in for postgres:16-alpine where no registry is reachable (deploy/compose-local.sh):
# Debian bookworm's PostgreSQL 15 on the local base, with the official image's contract as far as
# docker-compose.yml uses it: POSTGRES_USER / POSTGRES_PASSWORD / POSTGRES_DB create the role
# and database on first start, data in /var/lib/postgresql/data, pg_isready on PATH.
ARG BASE=quadloc-base:bookworm
FROM ${BASE}
# hadolint ignore=DL3008
RUN apt-get update \
    && apt-get install -y --no-install-recommends postgresql-15 \
    && rm -rf /var/lib/apt/lists/* \
    && mkdir -p /var/lib/postgresql/data /var/run/postgresql \
    && chown -R postgres:postgres /var/lib/postgresql /var/run/postgresql
COPY postgres-entrypoint.sh /usr/local/bin/postgres-entrypoint.sh
ENV PATH=/usr/lib/postgresql/15/bin:$PATH \
    PGDATA=/var/lib/postgresql/data
USER postgres
VOLUME ["/var/lib/postgresql/data"]
EXPOSE 5432
CMD ["bash", "/usr/local/bin/postgres-entrypoint.sh"]
