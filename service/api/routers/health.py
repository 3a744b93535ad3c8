"""Probes and metrics: ``/healthz`` (alive), ``/readyz`` (database + default map), ``/metrics``."""

from __future__ import annotations

import logging

from fastapi import APIRouter, Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest
from sqlalchemy.exc import SQLAlchemyError

from quadloc.maps.errors import MapNotFound, StoreUnavailable
from quadloc.service.api.deps import MetricsDep, SettingsDep, StoreDep
from quadloc.service.api.errors import ProblemError, log_database_error, problem_responses
from quadloc.service.schemas.common import HealthOut

__all__ = ["router"]

log = logging.getLogger("quadloc.api")

router = APIRouter(tags=["operations"])


@router.get("/healthz", response_model=HealthOut, summary="Liveness probe",
            description="200 while the process serves requests (no dependency checked).",
            responses={200: {"content": {"application/json": {
                "example": {"status": "ok", "checks": {}}}}}})
async def healthz() -> HealthOut:
    return HealthOut(status="ok")


@router.get("/readyz", response_model=HealthOut, summary="Readiness probe",
            description="200 when the database answers and the default map compiles; "
                        "503 problem otherwise.",
            responses={**problem_responses(503), 200: {"content": {"application/json": {
                "example": {"status": "ready",
                            "checks": {"database": "ok", "default_map": "chess v1"}}}}}})
def readyz(store: StoreDep, settings: SettingsDep) -> HealthOut:
    checks: dict[str, str] = {}
    # The probe needs no key: its answer names the failing check only; the driver's text (host,
    # database, SQL) goes to the log.
    try:
        store.ping()
        checks["database"] = "ok"
        if settings.default_map_id:
            compiled = store.compiled(settings.default_map_id)
            checks["default_map"] = f"{compiled.map_id} v{compiled.version}"
    except MapNotFound as exc:
        raise ProblemError("not-ready", "default_map: not found",
                           field="default_map", message="not found") from exc
    except (StoreUnavailable, SQLAlchemyError) as exc:  # any driver error means not ready
        log_database_error("readiness: database unavailable", exc)
        raise ProblemError("not-ready", "database: unavailable",
                           field="database", message="unavailable") from exc
    except Exception as exc:  # the stored default map does not load (logged)
        log.exception("readiness: default map %r not loadable", settings.default_map_id)
        raise ProblemError("not-ready", "default_map: not loadable",
                           field="default_map", message="not loadable") from exc
    return HealthOut(status="ready", checks=checks)


@router.get("/metrics", summary="Prometheus metrics",
            response_class=Response,
            responses={200: {"content": {CONTENT_TYPE_LATEST: {
                "schema": {"type": "string"},
                "example": "# TYPE quadloc_localizations_total counter\n"
                           'quadloc_localizations_total{outcome="localized"} 42.0\n'}},
                             "description": "Prometheus text exposition format."}})
async def metrics(m: MetricsDep) -> Response:
    return Response(generate_latest(m.registry), media_type=CONTENT_TYPE_LATEST)
