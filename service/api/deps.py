"""Shared FastAPI dependencies (``Annotated`` aliases) for the routers."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from maps.store import MapStore
from service.api.metrics import ApiMetrics
from service.api.solver import Solver
from service.settings import Settings

__all__ = ["MetricsDep", "SettingsDep", "SolverDep", "StoreDep"]


def get_store(request: Request) -> MapStore:
    return request.app.state.store


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_solver(request: Request) -> Solver:
    return request.app.state.solver


def get_metrics(request: Request) -> ApiMetrics:
    return request.app.state.metrics


StoreDep = Annotated[MapStore, Depends(get_store)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
SolverDep = Annotated[Solver, Depends(get_solver)]
MetricsDep = Annotated[ApiMetrics, Depends(get_metrics)]
