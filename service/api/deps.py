"""Shared FastAPI dependencies (``Annotated`` aliases) for the routers.

They are ``async def`` on purpose: they only read ``app.state``, and a plain ``def`` dependency
costs a threadpool round trip per request.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from maps.store import MapStore
from service.api.map_cache import MapCache
from service.api.metrics import ApiMetrics
from service.api.solver import Solver
from service.settings import Settings

__all__ = ["MapCacheDep", "MetricsDep", "SettingsDep", "SolverDep", "StoreDep"]


async def get_store(request: Request) -> MapStore:
    return request.app.state.store


async def get_settings(request: Request) -> Settings:
    return request.app.state.settings


async def get_solver(request: Request) -> Solver:
    return request.app.state.solver


async def get_map_cache(request: Request) -> MapCache:
    return request.app.state.map_cache


async def get_metrics(request: Request) -> ApiMetrics:
    return request.app.state.metrics


StoreDep = Annotated[MapStore, Depends(get_store)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
SolverDep = Annotated[Solver, Depends(get_solver)]
MetricsDep = Annotated[ApiMetrics, Depends(get_metrics)]
MapCacheDep = Annotated[MapCache, Depends(get_map_cache)]
