"""Property-based fuzzing of the OpenAPI schema with schemathesis (in-process ASGI app).

Every operation gets a bounded number of generated requests (valid and invalid); the checks
assert no 5xx, documented status codes and content types, and responses conforming to the
schema. Not checked: that every schema-valid request is accepted (``positive_data_acceptance``):
the API also enforces semantic rules JSON Schema does not express (a box's xmax > xmin, exactly
one of ellipse/box, unit quaternions, ``robust_scale`` only with ``robust``, known map
categories), which answer 422 naming the field. The app has a read+write API key, sent with
every generated request (schemathesis' auth check also replays requests with missing/invalid
credentials and expects 401/403). The apps run on temp SQLite DBs (pytest's ``tmp_path_factory``,
cleaned up by pytest) seeded with the demo map; they are built by module-scoped fixtures, not at
import time, and their stores are closed at teardown.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from schemathesis.specs.openapi.checks import positive_data_acceptance

from service.api.app import seed_demo_map
from service.localization.types import METRICS, ROBUST_KERNELS
from service.settings import hash_api_key
from tests.conftest import make_test_app

_KEY = "fuzz-key"


def _fuzz_app(tmp_path_factory: pytest.TempPathFactory, name: str) -> Any:
    return make_test_app(tmp_path_factory.mktemp(name), solve_time_budget_ms=200.0,
                         api_keys=f"{hash_api_key(_KEY)}:read+write")


@pytest.fixture(scope="module")
def fuzz_app(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    app = _fuzz_app(tmp_path_factory, "fuzz")
    yield app
    app.state.store.close()


# The committed document (a file read, no app at import time); tests/test_api_openapi.py checks
# that it is the app's. Each case is sent to the fixture's app (``schema.app``) in process.
schema = schemathesis.openapi.from_path(
    Path(__file__).resolve().parents[1] / "docs" / "openapi.json")


@schema.parametrize()
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
def test_api_conforms_and_never_fails(case: schemathesis.Case, fuzz_app: Any) -> None:
    # The default map cannot be deleted (409 default-map); re-seed anyway (a no-op while it
    # exists) so that /readyz's answer never depends on the order of generated requests.
    seed_demo_map(fuzz_app.state.store)
    fuzz_app.state.map_cache.invalidate("chess")
    case.operation.schema.app = fuzz_app  # ASGI transport: no network, no server
    case.call_and_validate(app=fuzz_app, headers={"X-API-Key": _KEY},
                           excluded_checks=[positive_data_acceptance])


# --------------------------------------------------------------------------------------------
# Plausible-but-wild frames that reach deep into the solver (schemathesis' random labels rarely
# match the map's categories, so it mostly stops at label matching).

_LABELS = ["TV", "Xbox", "Chair", "Timer", "Games", "Interruptor", "Gamepad", "Sofa"]
_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


def _ellipse() -> st.SearchStrategy[dict]:
    return st.fixed_dictionaries({
        "cx": st.floats(-2000, 2000), "cy": st.floats(-2000, 2000),
        "a": st.floats(0.5, 3000), "b": st.floats(0.5, 3000), "angle": st.floats(-7, 7)})


_detection = st.fixed_dictionaries(
    {"ellipse": _ellipse(), "label": st.sampled_from(_LABELS)},
    optional={"sigma": st.floats(1e-6, 1e3), "score": st.floats(0, 1)})
_quaternion = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(
    lambda q: sum(x * x for x in q) > 1e-3).map(
    lambda q: [x / sum(y * y for y in q) ** 0.5 for x in q])
_prior = st.fixed_dictionaries(
    {"world_from_camera": st.fixed_dictionaries(
        {"quaternion_wxyz": _quaternion,
         "translation_m": st.lists(st.floats(-20, 20), min_size=3, max_size=3)})},
    optional={"covariance": st.floats(1e-8, 10).map(lambda s: (np.eye(6) * s).tolist()),
              "convention": st.sampled_from(["opencv", "opengl"])})
_frame = st.fixed_dictionaries(
    {"camera": st.fixed_dictionaries({"fx": st.floats(1, 1e5), "fy": st.floats(1, 1e5),
                                      "cx": st.floats(-1000, 2000), "cy": st.floats(-1000, 2000),
                                      "width": st.integers(1, 4000),
                                      "height": st.integers(1, 4000)}),
     "detections": st.lists(_detection, max_size=10),
     "options": st.fixed_dictionaries(
         {"metric": st.sampled_from(list(METRICS)),
          "robust": st.sampled_from([None, *ROBUST_KERNELS]),
          "use_sigma": st.booleans(), "ransac_max_hypotheses": st.integers(1, 50),
          "output_convention": st.sampled_from(["opencv", "opengl"])})},
    optional={"prior": _prior})


@pytest.fixture(scope="module")
def wild_client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    """One client (one lifespan) for every generated frame; the store closes at teardown."""
    with TestClient(_fuzz_app(tmp_path_factory, "wild")) as client:
        yield client


@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(frame=_frame)
def test_wild_frames_never_fail_the_server(wild_client: TestClient, frame: dict) -> None:
    r = wild_client.post("/v1/maps/chess/localize", json=frame, headers={"X-API-Key": _KEY})
    assert r.status_code in (200, 422), r.text
    body = r.json()
    if r.status_code == 422:
        assert body["errors"] and body["errors"][0]["field"]
        return
    if body["localized"]:
        T = np.array(body["world_from_camera"]["matrix"])
        assert np.all(np.isfinite(T))
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-6)
        assert abs(np.linalg.norm(body["world_from_camera"]["quaternion_wxyz"]) - 1) < 1e-9
    else:
        assert body["reason"] and body["world_from_camera"] is None
