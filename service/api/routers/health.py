"""Probes and metrics: ``/healthz`` (alive), ``/readyz`` (database + default map), ``/metrics``."""

from __future__ import annotations

from fastapi import APIRouter, Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

from quadloc.service.api.deps import AppDep, MetricsDep
from quadloc.service.api.errors import problem_responses
from quadloc.service.schemas.common import HealthOut

__all__ = ["router"]

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
def readyz(app: AppDep) -> HealthOut:
    # The probe needs no key: its answer names the failing check only.
    return HealthOut(status="ready", checks=app.maps.readiness())


@router.get("/metrics", summary="Prometheus metrics",
            response_class=Response,
            responses={200: {"content": {CONTENT_TYPE_LATEST: {
                "schema": {"type": "string"},
                "example": "# TYPE quadloc_localizations_total counter\n"
                           'quadloc_localizations_total{outcome="localized"} 42.0\n'}},
                             "description": "Prometheus text exposition format."}})
async def metrics(m: MetricsDep) -> Response:
    return Response(generate_latest(m.registry), media_type=CONTENT_TYPE_LATEST)
