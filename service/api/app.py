"""The FastAPI application factory: the HTTP front end of the application
(:class:`quadloc.service.app.context.App`).

``create_app(settings)`` builds a self-contained app: its own application (map store migrated
at creation, demo Chess map seeded as ``settings.default_map_id`` when absent, solver slots,
sessions, build runner) and its own Prometheus registry. The routers translate HTTP to the
application's use cases and back; nothing else. Run it with ``quadloc serve`` or
``uvicorn quadloc.service.api.app:create_app --factory`` (settings from ``QUADLOC_*`` variables;
plain Uvicorn lacks ``quadloc serve``'s header-size and request-read limits: service/api/server.py).
"""

from __future__ import annotations

import json
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import Depends, FastAPI

from quadloc.maps.store import MapStore
from quadloc.service.api.deps import check_body_depth
from quadloc.service.api.docs_pages import install_offline_docs
from quadloc.service.api.errors import install_error_handlers
from quadloc.service.api.inspector import install_inspector
from quadloc.service.api.metrics import ApiMetrics, MetricsAndLimitsMiddleware
from quadloc.service.api.openapi import build_openapi
from quadloc.service.api.routers import build, health, localize, maps, sessions
from quadloc.service.app.context import App
from quadloc.service.schemas.common import API_VERSION
from quadloc.service.settings import Settings

__all__ = ["create_app", "openapi_document", "openapi_text"]

log = logging.getLogger("quadloc.api")

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


def create_app(settings: Settings | None = None, *, store: MapStore | None = None) -> FastAPI:
    """Build the QuadLoc app (see the module docstring). ``store`` overrides the database URL."""
    settings = settings or Settings()
    metrics = ApiMetrics()
    services = App.create(settings, store=store, observer=metrics)

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        # before serving: no request pays the compilation of the numeric kernels
        # (quadloc.factors.jit)
        services.start()
        services.warm_up()
        if not settings.keys:
            log.warning("no API key configured (QUADLOC_API_KEYS): the API is OPEN and must "
                        "only listen on loopback")
        yield
        services.close()

    app = FastAPI(
        title="QuadLoc", version=API_VERSION, description=DESCRIPTION, lifespan=lifespan,
        dependencies=[Depends(check_body_depth)],
        docs_url=None, redoc_url=None,  # served offline by install_offline_docs below
        openapi_tags=[
            {"name": "localization", "description": "Camera pose from detected objects."},
            {"name": "maps", "description": "Versioned ellipsoid maps."},
            {"name": "tracking", "description": "Tracking sessions fused with odometry."},
            {"name": "operations", "description": "Probes and metrics."},
        ],
    )
    app.state.settings = settings
    app.state.api_keys = settings.keys
    app.state.metrics = metrics
    app.state.services = services
    install_error_handlers(app)
    for router in (localize.router, maps.router, build.router, health.router,
                   sessions.router):
        app.include_router(router)
    install_offline_docs(app)
    install_inspector(app)
    app.add_middleware(MetricsAndLimitsMiddleware, metrics=metrics,
                       max_body_bytes=settings.max_body_bytes,
                       path_body_bytes={
                           "/v1/maps:build": services.builds.limits.max_body_bytes})
    app.openapi = lambda: build_openapi(app)  # type: ignore[method-assign]
    return app


def openapi_document() -> dict[str, Any]:
    """The API's OpenAPI document (built on an in-memory store, nothing seeded)."""
    app = create_app(Settings(seed_demo_map=False, api_keys=""), store=MapStore("sqlite://"))
    return build_openapi(app)


def openapi_text() -> str:
    """``docs/openapi.json`` as written by ``quadloc openapi --output`` (stable formatting)."""
    return json.dumps(openapi_document(), indent=2, ensure_ascii=False) + "\n"
