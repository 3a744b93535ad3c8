"""HTTP clients of the QuadLoc service: :class:`QuadLocClient` (sync) and
:class:`AsyncQuadLocClient` (asyncio), both on httpx, with the same methods.

Example::

    from quadloc_sdk import QuadLocClient, Camera, Detection, Ellipse

    with QuadLocClient("http://127.0.0.1:8000", api_key=None) as client:
        answer = client.localize(
            "chess",
            camera=Camera(fx=532.57, fy=531.54, cx=320, cy=240, width=640, height=480),
            detections=[Detection(label="TV", ellipse=Ellipse(cx=300, cy=200, a=80, b=40,
                                                              angle=0.1))],
        )
        if answer.localized:
            world_from_camera = answer.world_from_camera.as_matrix()   # 4x4, metres

Errors are raised as :mod:`quadloc_sdk.errors` exceptions; "not localized" is a normal answer
(``answer.localized is False``, ``answer.reason``). Retries follow
:class:`quadloc_sdk.retry.RetryPolicy` (429/503 and connection failures; never other 4xx).
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, cast
from urllib.parse import quote

import httpx

from quadloc_sdk.build import Recording, abuild_map, build_map, load_recording
from quadloc_sdk.errors import PreconditionFailed, QuadLocError, TransportError, error_from_response
from quadloc_sdk.models import (
    BatchLocalizeResponse,
    Calibration,
    Camera,
    Convention,
    Detection,
    Gravity,
    Hint,
    LocalizeOptions,
    LocalizeRequest,
    LocalizeResponse,
    MapRecord,
    MapSummary,
    MapVersion,
    PosePrior,
    SessionInfo,
    SessionOptions,
)
from quadloc_sdk.retry import RetryPolicy
from quadloc_sdk.session import (
    AsyncTrackingSession,
    TrackingSession,
    get_session,
    get_session_async,
    start_session,
    start_session_async,
)
from quadloc_sdk.transport import Call

__all__ = ["CALIBRATION_TIMEOUT_S", "DEFAULT_BASE_URL", "AsyncQuadLocClient", "QuadLocClient"]

SDK_VERSION = "0.1.0"
DEFAULT_BASE_URL = "http://127.0.0.1:8000"
DEFAULT_TIMEOUT = httpx.Timeout(30.0, connect=5.0)
#: Read timeout (s) of ``calibrate_map`` (synchronous: the server answers when the fit is done;
#: docs/map_building.md, "Calibrating the map", measures how long).
CALIBRATION_TIMEOUT_S = 600.0

MapDocument = Mapping[str, Any] | str | Path




def _segment(name: str, value: str) -> str:
    if not isinstance(value, str) or not value:
        raise ValueError(f"{name}: must be a non-empty string, got {value!r}")
    return quote(value, safe="")


def _dumps(field_name: str, payload: Any) -> bytes:
    try:
        return json.dumps(payload, allow_nan=False, separators=(",", ":")).encode()
    except ValueError as exc:
        raise ValueError(f"{field_name}: contains NaN or infinity (not valid JSON)") from exc
    except TypeError as exc:
        raise ValueError(f"{field_name}: not JSON-serialisable ({exc})") from exc


def _load_document(field_name: str, document: MapDocument) -> dict[str, Any]:
    if isinstance(document, str | Path):
        path = Path(document)
        try:
            data = json.loads(path.read_text())
        except OSError as exc:
            raise ValueError(f"{field_name}: cannot read {path}: {exc}") from exc
        except json.JSONDecodeError as exc:
            raise ValueError(f"{field_name}: {path} is not valid JSON: {exc}") from exc
    else:
        data = document
    if not isinstance(data, Mapping):
        raise ValueError(f"{field_name}: expected a JSON object, got {type(data).__name__}")
    return dict(data)


def _etag_value(etag: str) -> str:
    """Normalise a user-given ETag / content hash into a quoted entity tag for If-Match."""
    etag = etag.strip()
    if etag.startswith(('"', 'W/"')):
        return etag
    return f'"{etag}"'


class _Base:
    """Request building and response parsing shared by the sync and async clients."""

    #: API routes (relative to ``base_url``).
    MAPS = "/v1/maps"
    IMPORT_CHESS = "/v1/maps:import-chess"

    def __init__(
        self,
        base_url: str,
        api_key: str | None,
        retry: RetryPolicy | None,
    ) -> None:
        if not isinstance(base_url, str) or not base_url.startswith(("http://", "https://")):
            raise ValueError(f"base_url: must start with http:// or https://, got {base_url!r}")
        if api_key is not None and (not isinstance(api_key, str) or not api_key.strip()):
            raise ValueError("api_key: must be a non-empty string or None")
        self.base_url = base_url.rstrip("/")
        self.retry = retry if retry is not None else RetryPolicy()
        self._default_headers = {
            "Accept": "application/json, application/problem+json",
            "User-Agent": f"quadloc-sdk/{SDK_VERSION} httpx/{httpx.__version__}",
        }
        if api_key is not None:
            self._default_headers["Authorization"] = f"Bearer {api_key.strip()}"

    # -- builders --------------------------------------------------------------------------
    def _json_call(
        self, method: str, path: str, field_name: str, payload: Any, **kw: Any
    ) -> Call:
        headers = {"Content-Type": "application/json", **kw.pop("headers", {})}
        return Call(method, path, body=_dumps(field_name, payload), headers=headers, **kw)

    def _map_path(self, map_id: str) -> str:
        return f"{self.MAPS}/{_segment('map_id', map_id)}"

    def _list_maps_call(self) -> Call:
        return Call("GET", self.MAPS, idempotent=True)

    def _get_map_call(self, map_id: str, version: int | None) -> Call:
        params = None
        if version is not None:
            if isinstance(version, bool) or not isinstance(version, int) or version < 1:
                raise ValueError(f"version: must be an integer >= 1, got {version!r}")
            params = {"version": version}
        return Call("GET", self._map_path(map_id), params=params, idempotent=True)

    def _versions_call(self, map_id: str) -> Call:
        return Call("GET", f"{self._map_path(map_id)}/versions", idempotent=True)

    def _calibrate_call(self, map_id: str, recording: Recording, version: int | None,
                        timeout_s: float) -> Call:
        # Not idempotent by the retry policy's rule (a POST); replaying it would refit and
        # store the same calibration again, harmless but slow: not replayed.
        return Call("POST", f"{self._map_path(map_id)}/calibration",
                    params=self._version_params(version), body=load_recording(recording),
                    headers={"Content-Type": "application/json"}, timeout_s=timeout_s)

    def _get_calibration_call(self, map_id: str, version: int | None) -> Call:
        return Call("GET", f"{self._map_path(map_id)}/calibration",
                    params=self._version_params(version), idempotent=True)

    def _map_versions(self, response: httpx.Response) -> list[MapVersion]:
        data = self._json(response)
        return [MapVersion.model_validate(v) for v in data["versions"]]

    def _create_map_call(self, document: MapDocument) -> Call:
        return self._json_call("POST", self.MAPS, "map", _load_document("map", document))

    def _import_chess_call(self, chess: MapDocument, map_id: str, name: str | None) -> Call:
        _segment("map_id", map_id)  # validates
        params: dict[str, Any] = {"map_id": map_id}
        if name is not None:
            params["name"] = name
        return self._json_call(
            "POST", self.IMPORT_CHESS, "chess", _load_document("chess", chess), params=params
        )

    @staticmethod
    def _check_update_args(if_match: str | None, expected_version: int | None) -> None:
        if (if_match is None) == (expected_version is None):
            raise ValueError(
                "update_map: give exactly one of if_match (the etag of get_map) or "
                "expected_version: updates never silently overwrite"
            )
        if if_match is not None and (not isinstance(if_match, str) or not if_match.strip()):
            raise ValueError(f"if_match: must be a non-empty ETag string, got {if_match!r}")
        if expected_version is not None and not (
            isinstance(expected_version, int) and not isinstance(expected_version, bool)
            and expected_version >= 1
        ):
            raise ValueError(
                f"expected_version: must be an integer >= 1, got {expected_version!r}"
            )

    def _update_map_call(self, map_id: str, document: MapDocument, if_match: str) -> Call:
        return self._json_call(
            "PUT", self._map_path(map_id), "map", _load_document("map", document),
            headers={"If-Match": _etag_value(if_match)},
        )

    def _etag_for_version(self, map_id: str, latest: MapRecord, expected_version: int) -> str:
        """ETag to send when the caller expects ``expected_version`` to be the latest.

        The server's concurrency token is the ETag (content hash); the version check is done
        here against the latest version just read, and the ETag then guards the gap between
        that read and the write (a concurrent update in between gives 412/409)."""
        if latest.version != expected_version:
            raise PreconditionFailed(
                status=412, method="PUT", url=self.base_url + self._map_path(map_id),
                problem={
                    "type": "urn:quadloc:problem:precondition-failed",
                    "title": "Precondition failed: the map changed",
                    "status": 412,
                    "detail": f"map {map_id!r} is at version {latest.version}, "
                              f"expected version {expected_version}",
                    "errors": [{"field": "expected_version",
                                "message": f"stale: latest is {latest.version}"}],
                },
            )
        if latest.etag:
            return latest.etag
        return _etag_value(latest.content_hash)

    def _delete_map_call(self, map_id: str) -> Call:
        return Call("DELETE", self._map_path(map_id))

    def _localize_request(
        self,
        request: LocalizeRequest | Mapping[str, Any] | None,
        camera: Camera | Mapping[str, Any] | None,
        detections: Sequence[Detection | Mapping[str, Any]] | None,
        prior: PosePrior | Mapping[str, Any] | None,
        gravity: Gravity | Mapping[str, Any] | None,
        options: LocalizeOptions | Mapping[str, Any] | None,
        frame_id: str | None,
        timestamp: float | None,
        hint: Hint | Mapping[str, Any] | None = None,
    ) -> LocalizeRequest:
        if request is not None:
            if any(x is not None for x in (camera, detections, prior, gravity, options,
                                           frame_id, timestamp, hint)):
                raise ValueError("localize: give either 'request' or the separate fields")
            return (request if isinstance(request, LocalizeRequest)
                    else LocalizeRequest.model_validate(request))
        if camera is None or detections is None:
            raise ValueError("localize: 'camera' and 'detections' are required")
        fields: dict[str, Any] = {"camera": camera, "detections": list(detections)}
        for name, value in (("prior", prior), ("gravity", gravity), ("options", options),
                            ("frame_id", frame_id), ("timestamp", timestamp), ("hint", hint)):
            if value is not None:
                fields[name] = value
        return LocalizeRequest.model_validate(fields)

    @staticmethod
    def _version_params(map_version: int | None) -> dict[str, Any] | None:
        if map_version is None:
            return None
        if isinstance(map_version, bool) or not isinstance(map_version, int) or map_version < 1:
            raise ValueError(f"map_version: must be an integer >= 1, got {map_version!r}")
        return {"version": map_version}

    def _localize_call(
        self, map_id: str, request: LocalizeRequest, map_version: int | None
    ) -> Call:
        return self._json_call("POST", f"{self._map_path(map_id)}/localize", "request",
                               request.to_wire(), idempotent=True,
                               params=self._version_params(map_version))

    def _batch_call(
        self,
        map_id: str,
        frames: Sequence[LocalizeRequest | Mapping[str, Any]],
        map_version: int | None,
    ) -> Call:
        if isinstance(frames, LocalizeRequest | Mapping) or not len(frames):
            raise ValueError("frames: must be a non-empty sequence of LocalizeRequest")
        models = [
            f if isinstance(f, LocalizeRequest) else LocalizeRequest.model_validate(f)
            for f in frames
        ]
        return self._json_call("POST", f"{self._map_path(map_id)}/localize:batch", "frames",
                               {"frames": [m.to_wire() for m in models]}, idempotent=True,
                               params=self._version_params(map_version))

    # -- parsers ---------------------------------------------------------------------------
    @staticmethod
    def _json(response: httpx.Response) -> Any:
        try:
            return response.json()
        except ValueError as exc:
            raise QuadLocError(
                f"{response.request.method} {response.request.url}: the server answered "
                f"{response.status_code} with a body that is not JSON"
            ) from exc

    def _map_record(self, response: httpx.Response) -> MapRecord:
        data = self._json(response)
        return MapRecord.model_validate({**data, "etag": response.headers.get("etag")})

    def _map_list(self, response: httpx.Response) -> list[MapSummary]:
        data = self._json(response)
        items = data["maps"] if isinstance(data, dict) and "maps" in data else data
        return [MapSummary.model_validate(m) for m in items]

    # -- retry loop pieces -----------------------------------------------------------------
    def _request_kwargs(self, call: Call) -> dict[str, Any]:
        kw: dict[str, Any] = {
            "params": call.params,
            "content": call.body,
            "headers": {**self._default_headers, **call.headers},
        }
        if call.timeout_s is not None:
            kw["timeout"] = httpx.Timeout(call.timeout_s, connect=5.0)
        return kw

    def _on_exception(self, call: Call, exc: httpx.TransportError, attempt: int) -> float:
        """Delay before the next attempt, or raise the SDK's TransportError."""
        if attempt < self.retry.max_attempts and self.retry.retryable_exception(
            exc, idempotent=call.idempotent
        ):
            return self.retry.backoff(attempt)
        raise TransportError(
            str(exc) or type(exc).__name__, method=call.method,
            url=self.base_url + call.path, attempts=attempt,
        ) from exc

    def _on_response(self, response: httpx.Response, attempt: int) -> float | None:
        """``None`` when the response is returned; a delay to retry; raises on errors."""
        if response.status_code < 400:
            return None
        if attempt < self.retry.max_attempts:
            delay = self.retry.delay_for_response(response, attempt)
            if delay is not None:
                return delay
        raise error_from_response(response, attempts=attempt)


class QuadLocClient(_Base):
    """Synchronous client. Thread-safe (one httpx connection pool); use as a context manager
    or call :meth:`close`.

    ``base_url``: e.g. ``http://127.0.0.1:8000``. ``api_key``: sent as
    ``Authorization: Bearer <key>`` (``None`` for an open loopback server). ``timeout``: seconds
    or an ``httpx.Timeout``. ``retry``: :class:`~quadloc_sdk.retry.RetryPolicy`. ``transport``: an
    httpx transport (e.g. ``httpx.MockTransport`` in tests). ``sleep``: waiting function (tests).
    """

    def __init__(
        self,
        base_url: str = DEFAULT_BASE_URL,
        api_key: str | None = None,
        *,
        timeout: float | httpx.Timeout = DEFAULT_TIMEOUT,
        retry: RetryPolicy | None = None,
        transport: httpx.BaseTransport | None = None,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        super().__init__(base_url, api_key, retry)
        self._sleep = sleep
        self._http = httpx.Client(base_url=self.base_url, timeout=timeout, transport=transport)

    def close(self) -> None:
        self._http.close()

    def start_session(self, map_id: str, *, camera: Camera | Mapping[str, Any],
                      convention: Convention = "opencv",
                      options: SessionOptions | Mapping[str, Any] | None = None
                      ) -> TrackingSession:
        """Start a tracking session (``POST /v1/maps/{id}/sessions``;
        :class:`quadloc_sdk.session.TrackingSession`, docs/tracking.md)."""
        return start_session(self, map_id, camera=camera, convention=convention,
                             options=options)

    def get_session(self, session_id: str) -> SessionInfo:
        """A tracking session's state (``GET /v1/sessions/{id}``)."""
        return get_session(self, session_id)

    def __enter__(self) -> QuadLocClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _send(self, call: Call) -> httpx.Response:
        attempt = 0
        while True:
            attempt += 1
            try:
                response = self._http.request(call.method, call.path,
                                              **self._request_kwargs(call))
            except httpx.TransportError as exc:
                self._sleep(self._on_exception(call, exc, attempt))
                continue
            delay = self._on_response(response, attempt)
            if delay is None:
                return response
            self._sleep(delay)

    # -- service ---------------------------------------------------------------------------
    def healthz(self) -> dict[str, Any]:
        """``GET /healthz``: the process is alive."""
        return cast(dict[str, Any], self._json(self._send(Call("GET", "/healthz",
                                                                idempotent=True))))

    def readyz(self) -> dict[str, Any]:
        """``GET /readyz``: database reachable and default map loadable (503 raises
        :class:`~quadloc_sdk.errors.ServiceUnavailable` after the retries)."""
        return cast(dict[str, Any], self._json(self._send(Call("GET", "/readyz",
                                                                idempotent=True))))

    def metrics(self) -> str:
        """``GET /metrics``: the Prometheus text exposition."""
        return self._send(Call("GET", "/metrics", idempotent=True)).text

    # -- maps ------------------------------------------------------------------------------
    def list_maps(self) -> list[MapSummary]:
        """All maps with their latest version and content hash."""
        return self._map_list(self._send(self._list_maps_call()))

    def get_map(self, map_id: str, version: int | None = None) -> MapRecord:
        """The latest (or the given) version of a map, with its ``etag``."""
        return self._map_record(self._send(self._get_map_call(map_id, version)))

    def list_versions(self, map_id: str) -> list[MapVersion]:
        """Every stored version of a map, ascending (``GET /v1/maps/{id}/versions``)."""
        return self._map_versions(self._send(self._versions_call(map_id)))

    def create_map(self, document: MapDocument) -> MapRecord:
        """Create a map (version 1) from a document in the docs/maps.md format (a dict, or a
        path to a JSON file). :class:`~quadloc_sdk.errors.Conflict` if the id exists."""
        return self._map_record(self._send(self._create_map_call(document)))

    def import_chess_map(
        self, chess: MapDocument, *, map_id: str, name: str | None = None
    ) -> MapRecord:
        """Create map ``map_id`` (version 1) from the 7-Scenes Chess format
        (``category_id_to_label``, ``objects[].ellipsoid {axes, R, center}``, world +Z up): a
        dict or a path to the JSON file. ``name`` defaults to the server's ("Chess")."""
        return self._map_record(self._send(self._import_chess_call(chess, map_id, name)))

    def update_map(
        self,
        map_id: str,
        document: MapDocument,
        *,
        if_match: str | None = None,
        expected_version: int | None = None,
    ) -> MapRecord:
        """Replace a map by a new version (n + 1). Say which version you edited, with exactly
        one of ``if_match`` (the ``etag`` of :meth:`get_map`) or ``expected_version`` (checked
        against the latest version, then guarded by its ETag). Stale ->
        :class:`~quadloc_sdk.errors.PreconditionFailed`; lost race ->
        :class:`~quadloc_sdk.errors.Conflict` (``PreconditionFailed`` is a ``Conflict``).

        Retries (:mod:`quadloc_sdk.retry`): like every call, retried on 429/503 and on connection
        failures before the request was sent; never after a failure that may have reached the
        server. Replaying this PUT is safe only because ``If-Match`` makes it conditional: if
        an earlier attempt did write, the replay no longer matches the ETag and fails with
        ``PreconditionFailed`` instead of overwriting (then :meth:`get_map` shows whether the
        latest version is yours)."""
        self._check_update_args(if_match, expected_version)
        if expected_version is not None:
            if_match = self._etag_for_version(map_id, self.get_map(map_id), expected_version)
        assert if_match is not None
        return self._map_record(self._send(self._update_map_call(map_id, document, if_match)))

    def build_map(self, recording: Any, *, map_id: str, if_match: str | None = None,
                  wait: bool = True, on_progress: Callable[..., None] | None = None,
                  poll_interval_s: float = 0.5, timeout_s: float = 600.0) -> Any:
        """Build a map from a recording (``POST /v1/maps:build``); see :mod:`quadloc_sdk.build`.
        Returns the :class:`quadloc_sdk.build.BuildJob` (finished unless ``wait=False``)."""
        return build_map(self, recording, map_id=map_id, if_match=if_match, wait=wait,
                         on_progress=on_progress, poll_interval_s=poll_interval_s,
                         timeout_s=timeout_s)

    def calibrate_map(self, map_id: str, recording: Recording, *, version: int | None = None,
                      timeout_s: float = CALIBRATION_TIMEOUT_S) -> Calibration:
        """Fit, store and return a map version's own calibration (``POST
        /v1/maps/{map_id}/calibration``; docs/map_building.md, "Calibrating the map") from the
        recording it was built from (a dict or a JSON file path, with ``holdout_every``).
        Synchronous: the answer comes when the fit is done (``timeout_s``, default
        :data:`CALIBRATION_TIMEOUT_S`)."""
        return Calibration.model_validate(self._json(self._send(
            self._calibrate_call(map_id, recording, version, timeout_s))))

    def get_calibration(self, map_id: str, *, version: int | None = None) -> Calibration:
        """A map version's stored calibration (``GET /v1/maps/{map_id}/calibration``;
        :class:`~quadloc_sdk.errors.NotFound` when it has none: the shipped one applies)."""
        return Calibration.model_validate(self._json(self._send(
            self._get_calibration_call(map_id, version))))

    def delete_map(self, map_id: str) -> None:
        """Delete a map and all its versions."""
        self._send(self._delete_map_call(map_id))

    # -- localization ----------------------------------------------------------------------
    def localize(
        self,
        map_id: str,
        request: LocalizeRequest | Mapping[str, Any] | None = None,
        *,
        camera: Camera | Mapping[str, Any] | None = None,
        detections: Sequence[Detection | Mapping[str, Any]] | None = None,
        prior: PosePrior | Mapping[str, Any] | None = None,
        gravity: Gravity | Mapping[str, Any] | None = None,
        options: LocalizeOptions | Mapping[str, Any] | None = None,
        frame_id: str | None = None,
        timestamp: float | None = None,
        map_version: int | None = None,
        hint: Hint | Mapping[str, Any] | None = None,
    ) -> LocalizeResponse:
        """Localize one frame against ``map_id`` (its latest version, or ``map_version``):
        pass a :class:`LocalizeRequest` or its fields (``hint``: :class:`quadloc_sdk.models.Hint`,
        where the camera roughly is). Invalid input raises ``pydantic.ValidationError`` (a
        ``ValueError`` naming the field) before sending."""
        req = self._localize_request(request, camera, detections, prior, gravity, options,
                                     frame_id, timestamp, hint)
        return LocalizeResponse.model_validate(
            self._json(self._send(self._localize_call(map_id, req, map_version)))
        )

    def localize_batch(
        self,
        map_id: str,
        frames: Sequence[LocalizeRequest | Mapping[str, Any]],
        *,
        map_version: int | None = None,
    ) -> BatchLocalizeResponse:
        """Localize several frames in one request (the server bounds the count; all frames
        use the same map version). Results are in the order of ``frames``."""
        return BatchLocalizeResponse.model_validate(
            self._json(self._send(self._batch_call(map_id, frames, map_version)))
        )


class AsyncQuadLocClient(_Base):
    """asyncio client with the same methods as :class:`QuadLocClient` (awaitable). Use
    ``async with`` or ``await client.aclose()``."""

    def __init__(
        self,
        base_url: str = DEFAULT_BASE_URL,
        api_key: str | None = None,
        *,
        timeout: float | httpx.Timeout = DEFAULT_TIMEOUT,
        retry: RetryPolicy | None = None,
        transport: httpx.AsyncBaseTransport | None = None,
        sleep: Callable[[float], Any] = asyncio.sleep,
    ) -> None:
        super().__init__(base_url, api_key, retry)
        self._sleep = sleep
        self._http = httpx.AsyncClient(base_url=self.base_url, timeout=timeout,
                                       transport=transport)

    async def aclose(self) -> None:
        await self._http.aclose()

    async def start_session(self, map_id: str, *, camera: Camera | Mapping[str, Any],
                            convention: Convention = "opencv",
                            options: SessionOptions | Mapping[str, Any] | None = None
                            ) -> AsyncTrackingSession:
        """Start a tracking session (:class:`quadloc_sdk.session.AsyncTrackingSession`)."""
        return await start_session_async(self, map_id, camera=camera, convention=convention,
                                         options=options)

    async def get_session(self, session_id: str) -> SessionInfo:
        """A tracking session's state (``GET /v1/sessions/{id}``)."""
        return await get_session_async(self, session_id)

    async def __aenter__(self) -> AsyncQuadLocClient:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.aclose()

    async def _send(self, call: Call) -> httpx.Response:
        attempt = 0
        while True:
            attempt += 1
            try:
                response = await self._http.request(call.method, call.path,
                                                    **self._request_kwargs(call))
            except httpx.TransportError as exc:
                await self._sleep(self._on_exception(call, exc, attempt))
                continue
            delay = self._on_response(response, attempt)
            if delay is None:
                return response
            await self._sleep(delay)

    async def healthz(self) -> dict[str, Any]:
        return cast(dict[str, Any], self._json(await self._send(Call("GET", "/healthz",
                                                                      idempotent=True))))

    async def readyz(self) -> dict[str, Any]:
        return cast(dict[str, Any], self._json(await self._send(Call("GET", "/readyz",
                                                                      idempotent=True))))

    async def metrics(self) -> str:
        return (await self._send(Call("GET", "/metrics", idempotent=True))).text

    async def list_maps(self) -> list[MapSummary]:
        return self._map_list(await self._send(self._list_maps_call()))

    async def get_map(self, map_id: str, version: int | None = None) -> MapRecord:
        return self._map_record(await self._send(self._get_map_call(map_id, version)))

    async def list_versions(self, map_id: str) -> list[MapVersion]:
        return self._map_versions(await self._send(self._versions_call(map_id)))

    async def create_map(self, document: MapDocument) -> MapRecord:
        return self._map_record(await self._send(self._create_map_call(document)))

    async def import_chess_map(
        self, chess: MapDocument, *, map_id: str, name: str | None = None
    ) -> MapRecord:
        return self._map_record(await self._send(self._import_chess_call(chess, map_id, name)))

    async def update_map(
        self,
        map_id: str,
        document: MapDocument,
        *,
        if_match: str | None = None,
        expected_version: int | None = None,
    ) -> MapRecord:
        self._check_update_args(if_match, expected_version)
        if expected_version is not None:
            latest = await self.get_map(map_id)
            if_match = self._etag_for_version(map_id, latest, expected_version)
        assert if_match is not None
        return self._map_record(
            await self._send(self._update_map_call(map_id, document, if_match))
        )

    async def build_map(self, recording: Any, *, map_id: str, if_match: str | None = None,
                        wait: bool = True, on_progress: Callable[..., None] | None = None,
                        poll_interval_s: float = 0.5, timeout_s: float = 600.0) -> Any:
        """Build a map from a recording (``POST /v1/maps:build``); see :mod:`quadloc_sdk.build`."""
        return await abuild_map(self, recording, map_id=map_id, if_match=if_match, wait=wait,
                                on_progress=on_progress, poll_interval_s=poll_interval_s,
                                timeout_s=timeout_s)

    async def calibrate_map(self, map_id: str, recording: Recording, *,
                            version: int | None = None,
                            timeout_s: float = CALIBRATION_TIMEOUT_S) -> Calibration:
        """:meth:`QuadLocClient.calibrate_map`."""
        return Calibration.model_validate(self._json(await self._send(
            self._calibrate_call(map_id, recording, version, timeout_s))))

    async def get_calibration(self, map_id: str, *, version: int | None = None
                              ) -> Calibration:
        """:meth:`QuadLocClient.get_calibration`."""
        return Calibration.model_validate(self._json(await self._send(
            self._get_calibration_call(map_id, version))))

    async def delete_map(self, map_id: str) -> None:
        await self._send(self._delete_map_call(map_id))

    async def localize(
        self,
        map_id: str,
        request: LocalizeRequest | Mapping[str, Any] | None = None,
        *,
        camera: Camera | Mapping[str, Any] | None = None,
        detections: Sequence[Detection | Mapping[str, Any]] | None = None,
        prior: PosePrior | Mapping[str, Any] | None = None,
        gravity: Gravity | Mapping[str, Any] | None = None,
        options: LocalizeOptions | Mapping[str, Any] | None = None,
        frame_id: str | None = None,
        timestamp: float | None = None,
        map_version: int | None = None,
        hint: Hint | Mapping[str, Any] | None = None,
    ) -> LocalizeResponse:
        req = self._localize_request(request, camera, detections, prior, gravity, options,
                                     frame_id, timestamp, hint)
        return LocalizeResponse.model_validate(
            self._json(await self._send(self._localize_call(map_id, req, map_version)))
        )

    async def localize_batch(
        self,
        map_id: str,
        frames: Sequence[LocalizeRequest | Mapping[str, Any]],
        *,
        map_version: int | None = None,
    ) -> BatchLocalizeResponse:
        return BatchLocalizeResponse.model_validate(
            self._json(await self._send(self._batch_call(map_id, frames, map_version)))
        )
