"""``POST /v1/maps:build`` and ``GET /v1/build-jobs/{id}``: a real build from a small synthetic
recording, field-named errors, If-Match rules, stale jobs marked failed."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from quadloc.factors.camera import Camera, Ellipsoid, project_ellipsoid
from quadloc.factors.rotations import invert_pose, pose_matrix
from quadloc.maps.building.jobs import JobStore
from quadloc.maps.building.recording import recording_to_dict
from quadloc.service.app.builds import recording_of, validate_recording
from quadloc.service.app.conversions import held_out_frames_from_wire
from quadloc.service.schemas.recording import LEGACY_RECORDING_WARNING
from tests.conftest import make_test_app
from tests.support.helpers import wait_for_job

CAM = Camera(500.0, 500.0, 320.0, 240.0, 640, 480)
# two objects of one label and one of another, 1.5-2.5 m in front of a camera arc
OBJECTS = {"a": ("Box", Ellipsoid(np.array([0.3, 0.0, 2.0]), np.array([0.15, 0.1, 0.08]))),
           "b": ("Box", Ellipsoid(np.array([-0.4, 0.1, 2.3]), np.array([0.12, 0.12, 0.1]))),
           "c": ("Lamp", Ellipsoid(np.array([0.0, -0.3, 2.6]), np.array([0.08, 0.2, 0.08])))}


def _look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(np.array([0.0, -1.0, 0.0]), z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return pose_matrix(np.column_stack([x, y, z]), eye)


def _recording(n: int = 24) -> tuple[dict[str, Any], list[list[str]]]:
    frames, truth = [], []
    for i in range(n):
        ang = np.radians(-35 + 70 * i / (n - 1))
        eye = np.array([2.2 * np.sin(ang), 0.1 * np.cos(3 * ang), 2.2 - 2.2 * np.cos(ang)])
        T = _look_at(eye, np.array([0.0, 0.0, 2.2]))
        dets, ids = [], []
        for oid, (label, ell) in OBJECTS.items():
            e = project_ellipsoid(CAM, invert_pose(T), ell)
            dets.append({"label": label, "ellipse": {"cx": e.cx, "cy": e.cy, "a": e.a,
                                                     "b": e.b, "angle": e.angle}})
            ids.append(oid)
        frames.append((f"f{i}", T, dets))
        truth.append(ids)
    return recording_to_dict(CAM, frames, name="test room"), truth


@pytest.fixture
def client(tmp_path: Path):
    with TestClient(make_test_app(tmp_path)) as c:
        yield c


def test_build_new_map_then_new_version_with_if_match(client: TestClient) -> None:
    rec, truth = _recording()
    r = client.post("/v1/maps:build", params={"map_id": "room"}, json=rec)
    assert r.status_code == 202, r.text
    loc = r.headers["Location"]
    assert loc == f"/v1/build-jobs/{r.json()['job_id']}"
    job = wait_for_job(client, loc)
    assert job["status"] == "succeeded", job
    assert job["map_version"] == 1 and job["percent"] == 100.0
    m = client.get("/v1/maps/room").json()["map"]
    assert len(m["objects"]) == 3
    # every object is within 2 cm of a true one, of the right label
    for obj in m["objects"]:
        c = np.array(obj["center"] if "center" in obj else obj["ellipsoid"]["center"])
        d = {k: np.linalg.norm(c - e.center) for k, (_, e) in OBJECTS.items()}
        best = min(d, key=d.get)
        assert d[best] < 0.02 and OBJECTS[best][0] == obj["category"]
    # the report says which detections built which object: exact association here
    for o in job["report"]["objects"]:
        ids = {truth[d["frame_index"]][d["detection_index"]] for d in o["detections"]}
        assert len(ids) == 1 and len(o["detections"]) == len(truth)
        assert o["quality"]["n_views"] == len(truth)
    # an existing map needs If-Match
    r = client.post("/v1/maps:build", params={"map_id": "room"}, json=rec)
    assert r.status_code == 428
    assert r.json()["errors"][0]["field"] == "header.if-match"
    r = client.post("/v1/maps:build", params={"map_id": "room"}, json=rec,
                    headers={"If-Match": '"stale"'})
    assert r.status_code == 412
    etag = client.get("/v1/maps/room").headers["ETag"]
    r = client.post("/v1/maps:build", params={"map_id": "room"}, json=rec,
                    headers={"If-Match": etag})
    assert r.status_code == 202
    job = wait_for_job(client, r.headers["Location"])
    assert job["status"] == "succeeded" and job["map_version"] == 2


def test_invalid_recording_names_fields_and_stores_nothing(client: TestClient) -> None:
    rec, _ = _recording(4)
    rec["frames"][1]["detections"][0]["ellipse"]["a"] = -3
    rec["frames"][2]["world_from_camera"]["quaternion_wxyz"] = [2, 0, 0, 0]
    del rec["camera"]["fx"]
    r = client.post("/v1/maps:build", params={"map_id": "bad"}, json=rec)
    assert r.status_code == 422
    fields = {e["field"] for e in r.json()["errors"]}
    assert {"frames[1].detections[0].ellipse.a", "camera.fx"} == fields
    # past the schema, the poses' rules (unit quaternion, rotation matrix) name their field
    rec, _ = _recording(4)
    rec["frames"][2]["world_from_camera"]["quaternion_wxyz"] = [2, 0, 0, 0]
    rec["frames"][3]["world_from_camera"] = {"matrix": [[1, 0, 0, 0], [0, 2, 0, 0],
                                                        [0, 0, 1, 0], [0, 0, 0, 1]]}
    r = client.post("/v1/maps:build", params={"map_id": "bad"}, json=rec)
    assert r.status_code == 422
    assert {e["field"] for e in r.json()["errors"]} == {
        "frames[2].world_from_camera.quaternion_wxyz", "frames[3].world_from_camera"}
    assert client.get("/v1/maps/bad").status_code == 404
    r = client.post("/v1/maps:build", params={"map_id": "bad map!"}, json=_recording(4)[0])
    assert r.status_code == 422


def test_build_limits(tmp_path: Path) -> None:
    with TestClient(make_test_app(tmp_path, max_build_frames=3)) as c:
        r = c.post("/v1/maps:build", params={"map_id": "x"}, json=_recording(4)[0])
        assert r.status_code == 422
        assert r.json()["errors"][0]["field"] == "frames"


def test_building_scale_recording_needs_the_limit_configured(tmp_path: Path) -> None:
    """A recording above the in-process default (2,000 frames) is refused with a 422 naming
    ``frames`` by default and accepted (202, queued) where ``QUADLOC_MAX_BUILD_FRAMES`` allows
    it; nothing is stored by the refusal."""
    rec, _ = _recording(2001)
    with TestClient(make_test_app(tmp_path / "default")) as c:
        r = c.post("/v1/maps:build", params={"map_id": "big"}, json=rec)
        assert r.status_code == 422
        assert r.json()["errors"][0]["field"] == "frames"
        assert "2000" in r.json()["errors"][0]["message"]
        assert c.get("/v1/maps/big").status_code == 404
    with TestClient(make_test_app(tmp_path / "configured", max_build_frames=2500)) as c:
        r = c.post("/v1/maps:build", params={"map_id": "big"}, json=rec)
        assert r.status_code == 202, r.text
        assert r.json()["status"] in {"queued", "running"}


def test_build_limit_defaults_follow_the_runner() -> None:
    """Unset build limits take the runner's defaults: small in the API process, building-scale
    (a 6,000-frame, 30,000-detection, 7.2 MB recording in under 30 min) in the workers; a set
    limit applies to both."""
    from quadloc.service.app.builds import resolved_runner
    from quadloc.service.settings import Settings

    settings = Settings()
    assert resolved_runner(settings, "postgresql") == "queue"
    assert resolved_runner(settings, "sqlite") == "in-process"
    assert resolved_runner(Settings(build_runner="in-process"), "postgresql") == "in-process"
    local, queue = settings.build_limits_for("in-process"), settings.build_limits_for("queue")
    assert (local.max_frames, local.max_detections, local.time_budget_s) == (2000, 20_000, 120)
    assert queue.max_frames >= 6000 and queue.max_detections >= 30_000
    assert queue.time_budget_s >= 1800 and queue.max_body_bytes >= 8_000_000
    custom = Settings(max_build_frames=7000, build_time_budget_s=60, max_build_body_bytes=5000)
    for runner in ("in-process", "queue"):
        limits = custom.build_limits_for(runner)  # type: ignore[arg-type]
        assert (limits.max_frames, limits.time_budget_s, limits.max_body_bytes) == (
            7000, 60, 5000)


def test_build_body_limit_is_its_own(tmp_path: Path) -> None:
    """``POST /v1/maps:build`` has its own body limit (``QUADLOC_MAX_BUILD_BODY_BYTES``);
    other requests keep ``QUADLOC_MAX_BODY_BYTES`` (413 naming ``body``)."""
    rec, _ = _recording(120)
    body = json.dumps(rec)
    assert 20_000 < len(body) < 200_000
    headers = {"content-type": "application/json"}
    with TestClient(make_test_app(tmp_path / "a", max_body_bytes=20_000,
                                  max_build_body_bytes=200_000)) as c:
        r = c.post("/v1/maps:build", params={"map_id": "m"}, content=body, headers=headers)
        assert r.status_code == 202, r.text
        r = c.post("/v1/maps/chess/localize", content=body, headers=headers)
        assert r.status_code == 413 and r.json()["errors"][0]["field"] == "body"
    with TestClient(make_test_app(tmp_path / "b", max_build_body_bytes=20_000)) as c:
        r = c.post("/v1/maps:build", params={"map_id": "m"}, content=body, headers=headers)
        assert r.status_code == 413 and r.json()["errors"][0]["field"] == "body"


def test_unknown_job_is_404(client: TestClient) -> None:
    r = client.get("/v1/build-jobs/0000-1111")
    assert r.status_code == 404
    r = client.get("/v1/build-jobs/not%00an-id")
    assert r.status_code == 422 and r.json()["errors"][0]["field"] == "path.job_id"


def test_stale_running_job_is_marked_failed(tmp_path: Path) -> None:
    app = make_test_app(tmp_path)
    with TestClient(app) as c:
        jobs: JobStore = app.state.services.builds.jobs
        job = jobs.create("lost", None)
        jobs.progress(job.job_id, "associating", 10.0, 0)
        assert jobs.fail_stale(3600.0) == 0  # fresh heartbeat: left alone
        # pretend the heartbeat stopped long ago (the replica died)
        from quadloc.maps.building.jobs import jobs_table

        with app.state.services.store.engine.begin() as conn:
            conn.execute(jobs_table.update().values(
                updated_at=job.updated_at.replace(year=2000)))
        out = c.get(f"/v1/build-jobs/{job.job_id}").json()
        assert out["status"] == "failed" and out["error"]["reason"] == "runner_lost"
        # a late heartbeat from the lost runner does not revive it
        assert jobs.progress(job.job_id, "refining", 60.0, 1) is False
        assert jobs.get(job.job_id).status == "failed"


def test_jobs_table_mirrors_the_migration(tmp_path: Path) -> None:
    import sqlalchemy as sa

    from quadloc.maps.building.jobs import jobs_table
    from quadloc.maps.store import MapStore

    with MapStore(f"sqlite:///{tmp_path / 'j.db'}") as store:
        insp = sa.inspect(store.engine)
        assert {c["name"] for c in insp.get_columns(jobs_table.name)} == set(jobs_table.c.keys())
        migrated = {c["name"] for c in insp.get_check_constraints(jobs_table.name)}
        declared = {c.name for c in jobs_table.constraints if isinstance(c, sa.CheckConstraint)}
        assert declared == migrated == {"ck_quadloc_build_jobs_status"}


def _old_heartbeat(app: Any, job_id: str) -> None:
    """Pretend the job's heartbeat stopped long ago."""
    from quadloc.maps.building.jobs import jobs_table

    with app.state.services.store.engine.begin() as conn:
        conn.execute(jobs_table.update().where(jobs_table.c.job_id == job_id).values(
            updated_at=app.state.services.builds.jobs.get(job_id).updated_at.replace(year=2000)))


def test_a_restarted_replica_marks_the_running_job_failed_at_startup(tmp_path: Path) -> None:
    app = make_test_app(tmp_path)
    with TestClient(app):
        job = app.state.services.builds.jobs.create("lost", None)
        app.state.services.builds.jobs.progress(job.job_id, "refining", 60.0, 3)
        _old_heartbeat(app, job.job_id)  # the replica died mid-build
    restarted = make_test_app(tmp_path)  # same database
    with TestClient(restarted):
        out = restarted.state.services.builds.jobs.get(job.job_id)  # no status read needed
        assert out.status == "failed" and out.error["reason"] == "runner_lost"


class _BlockedBuild:
    """Stands in for ``build_map``: reports progress until released, then fails the build
    cleanly (no map), so that tests control how long a build runs."""

    def __init__(self) -> None:
        import threading

        self.release = threading.Event()
        self.started = threading.Event()

    def __call__(self, recording: Any, *, map_id: str, progress: Any, deadline: Any) -> Any:
        from quadloc.maps.building.build import BuildTimeoutError

        self.started.set()
        while not self.release.wait(0.01):
            progress("associating", 10.0, 0)
        raise BuildTimeoutError("released by the test")


def test_a_full_build_queue_answers_503_with_retry_after(tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    import quadloc.service.app.builds as bj

    blocked = _BlockedBuild()
    monkeypatch.setattr(bj, "build_map", blocked)
    app = make_test_app(tmp_path, max_concurrent_builds=1, max_queued_builds=1)
    rec = _recording(6)[0]
    with TestClient(app) as c:
        first = c.post("/v1/maps:build", params={"map_id": "one"}, json=rec)
        assert first.status_code == 202
        assert blocked.started.wait(10)
        queued = c.post("/v1/maps:build", params={"map_id": "two"}, json=rec)
        assert queued.status_code == 202 and queued.json()["status"] == "queued"
        full = c.post("/v1/maps:build", params={"map_id": "three"}, json=rec)
        assert full.status_code == 503
        assert int(full.headers["Retry-After"]) == bj.BUSY_RETRY_AFTER_S
        assert full.json()["type"].endswith("busy")
        # the request thread answered at once; the builds run in the runner's thread
        assert sorted(app.state.services.builds.runner.pending()) == sorted(
            [first.json()["job_id"], queued.json()["job_id"]])
        blocked.release.set()
        for r in (first, queued):
            job = wait_for_job(c, r.headers["Location"], timeout_s=30)
            assert job["error"]["reason"] == "time_budget_exceeded"
        # room again
        again = c.post("/v1/maps:build", params={"map_id": "four"}, json=rec)
        assert again.status_code == 202
        wait_for_job(c, again.headers["Location"], timeout_s=30)


def test_queued_jobs_beat_while_waiting_and_a_lost_job_stores_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import quadloc.service.app.builds as bj

    blocked = _BlockedBuild()
    monkeypatch.setattr(bj, "build_map", blocked)
    monkeypatch.setattr(bj, "HEARTBEAT_S", 0.0)
    app = make_test_app(tmp_path, max_concurrent_builds=1, max_queued_builds=1)
    rec = _recording(6)[0]
    with TestClient(app) as c:
        jobs: JobStore = app.state.services.builds.jobs
        first = c.post("/v1/maps:build", params={"map_id": "one"}, json=rec).json()["job_id"]
        assert blocked.started.wait(10)
        second = c.post("/v1/maps:build", params={"map_id": "two"}, json=rec).json()["job_id"]
        _old_heartbeat(app, second)
        t0 = time.monotonic()
        while jobs.get(second).updated_at.year == 2000 and time.monotonic() - t0 < 10:
            time.sleep(0.02)
        assert jobs.get(second).updated_at.year > 2000  # refreshed by the running build
        assert jobs.fail_stale(3600.0) == 0
        # another replica's sweep marks the running job failed: its runner stops. The runner
        # beats every 0 s; pause its beats for the sweep (a beat already past its check may
        # still land after _old_heartbeat: the sweep is retried), then let it beat again.
        monkeypatch.setattr(bj, "HEARTBEAT_S", 3600.0)
        for _ in range(5):
            _old_heartbeat(app, first)
            if (failed := jobs.fail_stale(60.0)) == 1:
                break
        assert failed == 1
        monkeypatch.setattr(bj, "HEARTBEAT_S", 0.0)
        t0 = time.monotonic()
        while first in app.state.services.builds.runner.pending() and time.monotonic() - t0 < 10:
            time.sleep(0.02)
        assert first not in app.state.services.builds.runner.pending()
        out = jobs.get(first)
        assert out.status == "failed" and out.error["reason"] == "runner_lost"
        blocked.release.set()
        wait_for_job(c, f"/v1/build-jobs/{second}", timeout_s=30)
        assert c.get("/v1/maps/one").status_code == 404


@pytest.mark.parametrize(("where", "typo", "field"), [
    ("detection", "sigmaa", "frames[0].detections[0].sigmaa"),
    ("top", "refine_camera_pose", "refine_camera_pose"),
    ("frame", "world_from_camara", "frames[0].world_from_camara"),
    ("top", "holdout", "holdout"),
])
def test_recording_typos_are_refused_naming_them(client: TestClient, where: str, typo: str,
                                                 field: str) -> None:
    """The issue's typos: a misspelt field is never silently ignored (before, ``sigmaa`` and
    ``refine_camera_pose: false`` were accepted and camera refinement silently stayed on)."""
    rec, _ = _recording(4)
    target = {"top": rec, "frame": rec["frames"][0],
              "detection": rec["frames"][0]["detections"][0]}[where]
    target[typo] = False if typo == "refine_camera_pose" else 0.5
    r = client.post("/v1/maps:build", params={"map_id": "typo"}, json=rec)
    assert r.status_code == 422, r.text
    assert [e["field"] for e in r.json()["errors"]] == [field]
    assert "extra" in r.json()["errors"][0]["message"].lower()
    assert client.get("/v1/maps/typo").status_code == 404


def _as_legacy(rec: dict[str, Any]) -> dict[str, Any]:
    """The recording in the deprecated form (intrinsics, boxes as arrays)."""
    old = json.loads(json.dumps(rec))
    old["intrinsics"] = old.pop("camera")
    for f in old["frames"]:
        for d in f["detections"]:
            if "box" in d:
                b = d["box"]
                d["box"] = [b["xmin"], b["ymin"], b["xmax"], b["ymax"]]
    return old


def test_pose_forms_conventions_and_legacy_form_give_the_same_recording() -> None:
    """quaternion_wxyz, quaternion_xyzw, matrix (OpenCV), and matrix in OpenGL axes (the
    OpenCV matrix times diag(1, -1, -1, 1), computed here independently) are one recording;
    the deprecated form too, with the deprecation warning."""
    rec, _ = _recording(5)
    rec["frames"][0]["detections"][0] = {"label": "Box", "box": {
        "xmin": 100.0, "ymin": 120.0, "xmax": 180.0, "ymax": 150.0}, "sigma": 0.3}
    base = recording_of(rec)
    assert base.warnings == ()
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    forms: dict[str, dict[str, Any]] = {}
    for name in ("xyzw", "matrix", "opengl"):
        doc = json.loads(json.dumps(rec))
        for f, fr in zip(doc["frames"], base.frames, strict=True):
            q = f["world_from_camera"]["quaternion_wxyz"]
            if name == "xyzw":
                f["world_from_camera"] = {"quaternion_xyzw": q[1:] + q[:1],
                                          "translation_m": f["world_from_camera"]
                                          ["translation_m"]}
            else:
                M = fr.world_from_camera @ (flip if name == "opengl" else np.eye(4))
                f["world_from_camera"] = {"matrix": M.tolist()}
        if name == "opengl":
            doc["convention"] = "opengl"
        forms[name] = doc
    forms["legacy"] = _as_legacy(rec)
    # the old form's integer ids are read as text
    legacy_ids = _as_legacy(rec)
    legacy_ids["frames"][1]["frame_id"] = 7
    legacy_ids["frames"][1]["detections"][0]["track_id"] = 3
    old = recording_of(legacy_ids)
    assert old.frames[1].frame_id == "7" and old.observations[3].track_id == "3"
    for name, doc in forms.items():
        other = recording_of(doc)
        assert len(other.frames) == len(base.frames)
        for a, b in zip(other.frames, base.frames, strict=True):
            np.testing.assert_allclose(a.world_from_camera, b.world_from_camera, atol=1e-12,
                                       err_msg=name)
        assert other.observations == base.observations, name
        assert other.warnings == ((LEGACY_RECORDING_WARNING,) if name == "legacy" else ())
    # the box became its inscribed ellipse, the sigma kept
    o = base.observations[0]
    assert (o.ellipse.cx, o.ellipse.cy, o.ellipse.a, o.ellipse.b) == (140.0, 135.0, 40.0, 15.0)
    assert o.sigma == 0.3


def test_holdout_keeps_every_kth_frame_out_of_the_build() -> None:
    rec, _ = _recording(10)
    rec["holdout_every"] = 3
    built = recording_of(rec)
    assert [f.source_index for f in built.frames] == [0, 1, 3, 4, 6, 7, 9]
    assert [f.frame_id for f in built.frames] == [f"f{i}" for i in (0, 1, 3, 4, 6, 7, 9)]
    assert {o.frame for o in built.observations} == set(range(7))
    assert any("3 of 10 frames held out" in w for w in built.warnings)
    camera, held = held_out_frames_from_wire(validate_recording(rec))
    assert [fid for fid, _, _ in held] == ["f2", "f5", "f8"]
    assert camera == CAM and all(len(d) == 3 for _, _, d in held)


def test_legacy_recording_builds_with_a_deprecation_warning(client: TestClient) -> None:
    rec, _ = _recording(12)
    rec["holdout_every"] = 4
    r = client.post("/v1/maps:build", params={"map_id": "old"}, json=_as_legacy(rec))
    assert r.status_code == 202, r.text
    job = wait_for_job(client, r.headers["Location"])
    assert job["status"] == "succeeded", job
    assert LEGACY_RECORDING_WARNING in job["report"]["warnings"]
    # frame indices of the report are positions in the document: no held-out frame built
    refs = [d for o in job["report"]["objects"] for d in o["detections"]]
    assert refs and all(d["frame_index"] % 4 != 3 for d in refs)
    assert all(d["frame_id"] == f"f{d['frame_index']}" for d in refs)
