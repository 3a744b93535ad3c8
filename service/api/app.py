"""The FastAPI application factory.

``create_app(settings)`` builds a self-contained app: its own map store (migrated at creation,
demo Chess map seeded as ``settings.default_map_id`` when absent), its own Prometheus registry,
its own solver slots. Run it with ``quadloc serve`` or
``uvicorn quadloc.service.api.app:create_app --factory`` (settings from ``QUADLOC_*`` variables;
plain Uvicorn lacks ``quadloc serve``'s header-size and request-read limits: service/api/server.py).
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import Depends, FastAPI
from fastapi.openapi.utils import get_openapi

from quadloc.factors.pose_residuals import compile_kernels
from quadloc.maps.cache import CompiledMapCache
from quadloc.maps.demo import DEMO_MAP_ID, load_demo_map
from quadloc.maps.errors import MapAlreadyExists, MapNotFound
from quadloc.maps.store import MapStore
from quadloc.service.api.build_jobs import install_map_building
from quadloc.service.api.deps import check_body_depth
from quadloc.service.api.docs_pages import install_offline_docs
from quadloc.service.api.errors import PROBLEM_MEDIA_TYPE, install_error_handlers
from quadloc.service.api.inspector import install_inspector
from quadloc.service.api.map_loader import MapLoader
from quadloc.service.api.metrics import ApiMetrics, MetricsAndLimitsMiddleware
from quadloc.service.api.routers import health, localize, maps, sessions
from quadloc.service.api.solver import Solver
from quadloc.service.settings import Settings
from quadloc.service.tracking.store import SessionStore

__all__ = ["API_VERSION", "build_openapi", "create_app", "seed_demo_map"]

log = logging.getLogger("quadloc.api")

API_VERSION = "1.0.0"

DESCRIPTION = """\
Object-based camera relocalization. A client sends the ellipses its object detector found in
one image (label, optional uncertainty) and the camera intrinsics; QuadLoc matches them to a
map of 3D ellipsoids and returns the camera pose `world_from_camera`, its covariance and a
confidence.

Conventions: pixels with origin at the top-left corner; ellipses `{cx, cy, a, b, angle}` with
SEMI-axes and the angle in RADIANS from +x towards +y; poses `world_from_camera` (metres) as
`quaternion_wxyz` (scalar first) + `translation_m` and a 4x4 matrix; OpenCV camera axes
(+X right, +Y down, +Z forward) unless `output_convention: "opengl"` (ARKit/ARCore);
covariances 6x6 in order [omega, v], camera (body) frame.

Errors are RFC 9457 `application/problem+json` naming each offending field; "not localized" is a
normal 200 answer. Authentication: `Authorization: Bearer <key>` or `X-API-Key: <key>` when the
server has keys configured (scopes `read` and `write`).
"""


def seed_demo_map(store: MapStore, map_id: str = DEMO_MAP_ID) -> bool:
    """Create the demo Chess map as ``map_id`` if absent. Returns True if it was created."""
    try:
        store.get(map_id)
        return False
    except MapNotFound:
        pass
    scene_map = load_demo_map()
    if map_id != scene_map.map_id:
        scene_map = type(scene_map).from_dict({**scene_map.to_dict(), "map_id": map_id})
    try:
        store.create(scene_map)
    except MapAlreadyExists:  # another worker seeded it first
        return False
    return True


def _tidy_openapi(schema: dict[str, Any]) -> dict[str, Any]:
    """Problem responses: schema under application/problem+json only; drop FastAPI's default
    HTTPValidationError (our 422s are problem documents)."""
    for path_item in schema.get("paths", {}).values():
        for op in path_item.values():
            for code, resp in op.get("responses", {}).items():
                content = resp.get("content", {})
                if str(code).startswith(("4", "5")) and PROBLEM_MEDIA_TYPE in content:
                    plain = content.pop("application/json", None)
                    if plain and "schema" in plain:
                        content[PROBLEM_MEDIA_TYPE]["schema"] = plain["schema"]
    comps = schema.get("components", {}).get("schemas", {})
    text = str(schema.get("paths"))
    for name in ("HTTPValidationError", "ValidationError"):
        if name in comps and f"#/components/schemas/{name}" not in text:
            del comps[name]
    return schema


def build_openapi(app: FastAPI) -> dict[str, Any]:
    """The app's OpenAPI document (cached on the app)."""
    if app.openapi_schema is None:
        schema = get_openapi(title=app.title, version=app.version, description=app.description,
                             routes=app.routes, tags=app.openapi_tags)
        app.openapi_schema = _tidy_openapi(schema)
    return app.openapi_schema


def create_app(settings: Settings | None = None, *, store: MapStore | None = None) -> FastAPI:
    """Build the QuadLoc app (see the module docstring). ``store`` overrides the database URL."""
    settings = settings or Settings()
    keys = settings.keys
    if store is None:
        store = MapStore(settings.effective_database_url,
                         cache=CompiledMapCache(settings.map_cache_ttl_s))
    if (settings.seed_demo_map and settings.default_map_id
            and seed_demo_map(store, settings.default_map_id)):
        log.info("seeded the demo Chess map as %r", settings.default_map_id)

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        # before serving: no request pays the compilation of the numeric kernels
        # (quadloc.factors.jit)
        compile_kernels()
        if not keys:
            log.warning("no API key configured (QUADLOC_API_KEYS): the API is OPEN and must "
                        "only listen on loopback")
        yield
        app.state.map_loader.close()
        store.close()

    app = FastAPI(
        title="QuadLoc", version=API_VERSION, description=DESCRIPTION, lifespan=lifespan,
        dependencies=[Depends(check_body_depth)],
        docs_url=None, redoc_url=None,  # served offline by install_offline_docs below
        openapi_tags=[
            {"name": "localization", "description": "Camera pose from detected objects."},
            {"name": "maps", "description": "Versioned ellipsoid maps."},
            {"name": "operations", "description": "Probes and metrics."},
        ],
    )
    metrics = ApiMetrics()
    app.state.settings = settings
    app.state.api_keys = keys
    app.state.store = store
    app.state.metrics = metrics
    app.state.map_loader = MapLoader(store, settings.solve_time_budget_ms / 1e3)
    app.state.solver = Solver(metrics, settings.max_concurrent_solves,
                              settings.solve_queue_timeout_s, settings.solve_time_budget_ms,
                              settings.max_detections, settings.batch_time_budget_ms)
    install_error_handlers(app)
    app.include_router(localize.router)
    app.include_router(maps.router)
    install_map_building(app, store, settings)
    app.include_router(health.router)
    app.state.sessions = SessionStore(settings.max_sessions, settings.session_idle_timeout_s)
    app.include_router(sessions.router)
    install_offline_docs(app)
    install_inspector(app)
    app.add_middleware(MetricsAndLimitsMiddleware, metrics=metrics,
                       max_body_bytes=settings.max_body_bytes)
    app.openapi = lambda: build_openapi(app)  # type: ignore[method-assign]
    return app
