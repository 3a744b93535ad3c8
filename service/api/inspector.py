"""The visual inspector: the ``/inspector`` page (assets in ``service/api/static/inspector``) and
the content negotiation of a localization drawn as SVG (``Accept: image/svg+xml`` on ``POST
/v1/maps/{map_id}/localize``; the drawing: :mod:`quadloc.service.app.drawing`). What is drawn:
docs/design/service.md#visual-inspector.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles

from quadloc.service.schemas.examples import LOCALIZE_EXAMPLE

__all__ = ["INSPECTOR_HEADERS", "SVG_HEADERS", "SVG_MEDIA_TYPE", "install_inspector",
           "wants_svg"]

SVG_MEDIA_TYPE = "image/svg+xml"
STATIC_DIR = Path(__file__).resolve().parent / "static" / "inspector"
STATIC_URL = "/static/inspector"
#: The inspector page's Content-Security-Policy: nothing from another origin, and no inline
#: script at all (the SVG answers it inserts carry only an inline <style>).
#: No other site may frame it (``frame-ancestors``: clickjacking).
INSPECTOR_CSP = ("default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
                 "img-src 'self' data:; font-src 'self'; connect-src 'self'; "
                 "frame-ancestors 'none'; base-uri 'none'; form-action 'self'")
#: Headers of the inspector page.
INSPECTOR_HEADERS = {"Content-Security-Policy": INSPECTOR_CSP,
                     "X-Content-Type-Options": "nosniff"}
#: Headers of a localization drawn as SVG: the document opened on its own (a new tab, a saved
#: link) runs nothing and loads nothing (only its inline <style>), no other site may frame it,
#: and the browser never sniffs it as another type.
SVG_HEADERS = {"Content-Security-Policy": "default-src 'none'; style-src 'unsafe-inline'; "
                                          "frame-ancestors 'self'",
               "X-Content-Type-Options": "nosniff"}


def _media_ranges(accept: str) -> dict[str, float]:
    """``{media type: q}`` of an ``Accept`` header (parameters other than ``q`` ignored)."""
    out: dict[str, float] = {}
    for part in accept.split(","):
        fields = [f.strip() for f in part.split(";")]
        if not fields[0]:
            continue
        q = 1.0
        for f in fields[1:]:
            if f.lower().startswith("q="):
                try:
                    q = float(f[2:])
                except ValueError:
                    q = 0.0
        out[fields[0].lower()] = max(q, out.get(fields[0].lower(), 0.0))
    return out


def wants_svg(accept: str | None) -> bool:
    """True when the ``Accept`` header asks for ``image/svg+xml`` (q > 0) at least as much as
    for JSON (``application/json``, ``application/*`` or ``*/*``)."""
    if not accept:
        return False
    ranges = _media_ranges(accept)
    svg = ranges.get(SVG_MEDIA_TYPE, 0.0)
    json_q = max(ranges.get("application/json", 0.0), ranges.get("application/*", 0.0))
    return svg > 0.0 and svg >= json_q


def install_inspector(app: FastAPI) -> None:
    """Add ``/inspector``, its example request and its static assets to ``app``."""
    app.mount(STATIC_URL, StaticFiles(directory=STATIC_DIR), name="inspector-static")
    router = APIRouter(include_in_schema=False)

    @router.get("/inspector")
    def inspector_page() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html", media_type="text/html",
                            headers=INSPECTOR_HEADERS)

    @router.get("/inspector/example.json")
    def inspector_example() -> JSONResponse:
        return JSONResponse(LOCALIZE_EXAMPLE)

    app.include_router(router)
