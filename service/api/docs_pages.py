"""Offline API documentation: ``/docs`` (Swagger UI) and ``/redoc`` (ReDoc) with the assets of
the installed ``fastapi-offline`` package, never a CDN. Why:
docs/design/service.md#offline-api-docs.
"""

from __future__ import annotations

from pathlib import Path

import fastapi_offline
from fastapi import FastAPI, Request
from fastapi.openapi.docs import (
    get_redoc_html,
    get_swagger_ui_html,
    get_swagger_ui_oauth2_redirect_html,
)
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

__all__ = ["DOCS_ASSETS", "DOCS_STATIC_DIR", "DOCS_STATIC_URL", "SAME_ORIGIN_ONLY_CSP",
           "install_offline_docs"]

#: Directory of the vendored assets inside the installed fastapi-offline package.
DOCS_STATIC_DIR = Path(fastapi_offline.__file__).resolve().parent / "static"
#: URL prefix the assets are served under.
DOCS_STATIC_URL = "/static/docs"
#: The files the pages load (checked at start: a broken install fails loudly, not blank).
DOCS_ASSETS = ("swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js", "favicon.png")
#: Content-Security-Policy of the HTML pages (docs and inspector): every script, style, image,
#: font and fetch from this server only (ReDoc's footer would otherwise fetch its logo from
#: cdn.redoc.ly; the browser now blocks that instead of trying the network). Inline scripts and
#: styles are FastAPI's page templates; ReDoc runs its search in a ``blob:`` worker.
SAME_ORIGIN_ONLY_CSP = ("default-src 'self'; script-src 'self' 'unsafe-inline'; "
                        "style-src 'self' 'unsafe-inline'; img-src 'self' data:; "
                        "font-src 'self' data:; connect-src 'self'; worker-src 'self' blob:")


def _same_origin_only(page: HTMLResponse) -> HTMLResponse:
    page.headers["Content-Security-Policy"] = SAME_ORIGIN_ONLY_CSP
    return page


def install_offline_docs(app: FastAPI, docs_url: str = "/docs", redoc_url: str = "/redoc") -> None:
    """Mount the assets and add the ``docs_url`` and ``redoc_url`` pages to ``app`` (create the
    app with ``docs_url=None, redoc_url=None``)."""
    missing = [name for name in DOCS_ASSETS if not (DOCS_STATIC_DIR / name).is_file()]
    if missing:
        raise RuntimeError(f"fastapi-offline assets missing from {DOCS_STATIC_DIR}: {missing}")
    app.mount(DOCS_STATIC_URL, StaticFiles(directory=DOCS_STATIC_DIR), name="docs-static")
    oauth2_url = app.swagger_ui_oauth2_redirect_url or "/docs/oauth2-redirect"

    @app.get(docs_url, include_in_schema=False)
    async def swagger_ui(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        return _same_origin_only(get_swagger_ui_html(
            openapi_url=f"{root}{app.openapi_url}", title=f"{app.title} - Swagger UI",
            oauth2_redirect_url=f"{root}{oauth2_url}",
            swagger_js_url=f"{root}{DOCS_STATIC_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{root}{DOCS_STATIC_URL}/swagger-ui.css",
            swagger_favicon_url=f"{root}{DOCS_STATIC_URL}/favicon.png",
            swagger_ui_parameters={"validatorUrl": None},
        ))

    @app.get(oauth2_url, include_in_schema=False)
    async def swagger_ui_redirect() -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()

    @app.get(redoc_url, include_in_schema=False)
    async def redoc(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        return _same_origin_only(get_redoc_html(
            openapi_url=f"{root}{app.openapi_url}", title=f"{app.title} - ReDoc",
            redoc_js_url=f"{root}{DOCS_STATIC_URL}/redoc.standalone.js",
            redoc_favicon_url=f"{root}{DOCS_STATIC_URL}/favicon.png",
            with_google_fonts=False,
        ))
