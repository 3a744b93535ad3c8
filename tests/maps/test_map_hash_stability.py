"""Map content hashes (the ETag) must not depend on the machine: the same map imported on
another CPU/LAPACK build, or through another route (rotation matrix vs quaternion), hashes the
same; a real change still changes the hash (issue 9)."""

from __future__ import annotations

import copy
import json
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from quadloc.factors.rotations import (
    ROTATION_EXACT_TOLERANCE,
    exact_norm,
    quaternion_wxyz_from_rotation,
    snap_to_rotation,
)
from quadloc.maps.demo import load_demo_map
from quadloc.maps.model import (
    HASH_DECIMALS,
    content_hash,
    scene_map_from_chess,
    scene_map_from_dict,
)
from tests.support.reference_data import CHESS_SCENE_PATH


@pytest.fixture(scope="module")
def chess_source() -> dict[str, Any]:
    return json.loads(CHESS_SCENE_PATH.read_text())


def _as_demo(scene_map):
    """The imported Chess map with the demo file's name and metadata, to compare hashes."""
    demo = load_demo_map()
    return replace(scene_map, name=demo.name, metadata=demo.metadata)


def _nudge(x: float, ulps: int) -> float:
    """``x`` moved by ``ulps`` units in the last place (sign gives the direction)."""
    for _ in range(abs(ulps)):
        x = float(np.nextafter(x, np.inf if ulps > 0 else -np.inf))
    return x


def test_chess_import_does_not_call_lapack(chess_source, monkeypatch):
    """The Chess rotations are orthonormal to ~1e-15: importing them must not run an SVD (whose
    last bits depend on the LAPACK build), so every machine stores the same quaternions."""
    def no_svd(*args, **kwargs):
        raise AssertionError("np.linalg.svd called while importing already-orthonormal rotations")

    monkeypatch.setattr(np.linalg, "svd", no_svd)
    imported = scene_map_from_chess(chess_source)
    demo = load_demo_map()
    assert content_hash(_as_demo(imported)) == demo.content_hash
    for a, b in zip(imported.objects, demo.objects, strict=True):
        np.testing.assert_allclose(a.quaternion_wxyz, b.quaternion_wxyz, rtol=0, atol=1e-15)


def test_rotation_and_quaternion_routes_hash_the_same(chess_source):
    """Route 1: the authors' rotation matrices (Chess importer). Route 2: the exported
    quaternion document (maps/data/chess.json, generic importer). Route 3: the generic importer
    given the rotation matrices. All hash the same."""
    demo = load_demo_map()
    by_rotation = scene_map_from_chess(chess_source)
    doc = demo.to_dict()
    for obj, src in zip(doc["objects"], chess_source["objects"], strict=True):
        del obj["quaternion_wxyz"]
        obj["rotation"] = src["ellipsoid"]["R"]
    generic_rotation = scene_map_from_dict(doc)
    assert content_hash(_as_demo(by_rotation)) == demo.content_hash
    assert generic_rotation.content_hash == demo.content_hash
    assert scene_map_from_dict(json.loads(demo.to_json())).content_hash == demo.content_hash


@pytest.mark.parametrize("ulps", [1, -1, 2, -3])
def test_rotations_perturbed_in_the_last_bits_hash_the_same(chess_source, ulps):
    """What another CPU's arithmetic does to the numbers: a few ulps in every rotation entry."""
    src = copy.deepcopy(chess_source)
    rng = np.random.default_rng(abs(ulps))
    for obj in src["objects"]:
        R = obj["ellipsoid"]["R"]
        for i in range(3):
            for j in range(3):
                R[i][j] = _nudge(R[i][j], int(rng.choice([-1, 1])) * ulps)
    moved = scene_map_from_chess(src)
    reference = scene_map_from_chess(chess_source)
    assert moved.to_dict() != reference.to_dict()  # the stored bits did change ...
    assert moved.content_hash == reference.content_hash  # ... the content hash did not


def test_svd_route_is_stable_against_lapack_last_bits(monkeypatch):
    """A rotation orthonormal only to ~1e-9 is snapped by SVD; an SVD that differs in the last
    bits (another LAPACK) gives a quaternion within 1e-15 and the same content hash."""
    rng = np.random.default_rng(7)
    R0 = snap_to_rotation(rng.normal(size=(3, 3)))
    R = R0 + 1e-9 * rng.normal(size=(3, 3))
    doc = {"map_id": "svd", "name": "SVD", "categories": ["c"],
           "objects": [{"object_id": "o", "category": "c", "center": [0.1, 0.2, 0.3],
                        "axes": [0.3, 0.2, 0.1], "rotation": R.tolist()}]}
    first = scene_map_from_dict(doc)
    real_svd = np.linalg.svd

    def other_lapack(a, *args, **kwargs):
        U, S, Vt = real_svd(a, *args, **kwargs)
        return np.nextafter(U, np.inf), S, np.nextafter(Vt, -np.inf)

    monkeypatch.setattr(np.linalg, "svd", other_lapack)
    second = scene_map_from_dict(doc)
    qa, qb = first.objects[0].quaternion_wxyz, second.objects[0].quaternion_wxyz
    assert not np.array_equal(qa, qb)  # the perturbation reached the stored numbers
    np.testing.assert_allclose(qa, qb, rtol=0, atol=1e-15)
    assert first.content_hash == second.content_hash


def test_hash_still_sees_real_changes():
    """Rounding to HASH_DECIMALS must not hide a change that means something."""
    demo = load_demo_map()
    step = 10.0 ** -(HASH_DECIMALS - 3)  # 1e-9 m or 1e-9 per quaternion component
    for key, i in (("center", 0), ("axes", 2), ("quaternion_wxyz", 1)):
        doc = demo.to_dict()
        doc["objects"][3][key][i] += step
        assert scene_map_from_dict(doc).content_hash != demo.content_hash, key
    doc = demo.to_dict()
    doc["up_axis"] = [0.0, 1e-9, 1.0]
    assert scene_map_from_dict(doc).content_hash != demo.content_hash
    assert replace(demo, version=2).content_hash != demo.content_hash
    # -0.0 and 0.0 are the same number: same hash
    doc = {"map_id": "z", "name": "Z", "categories": ["c"],
           "objects": [{"object_id": "o", "category": "c", "center": [0.0, 1.0, 2.0],
                        "axes": [0.3, 0.2, 0.1]}]}
    signed = copy.deepcopy(doc)
    signed["objects"][0]["center"][0] = -0.0
    assert scene_map_from_dict(signed).content_hash == scene_map_from_dict(doc).content_hash


def test_snap_to_rotation_keeps_rotations_and_snaps_the_rest():
    rng = np.random.default_rng(3)
    R = snap_to_rotation(rng.normal(size=(3, 3)))  # via SVD, det forced to +1
    # an exact rotation (to 1e-12) comes back bit for bit
    exact = quaternion_wxyz_from_rotation(R)
    np.testing.assert_array_equal(snap_to_rotation(R), R)
    # off by 1e-9: snapped onto the rotations, within 1e-9 of the input
    noisy = R + 1e-9 * rng.normal(size=(3, 3))
    S = snap_to_rotation(noisy)
    assert np.max(np.abs(S @ S.T - np.eye(3))) < 1e-14 and np.linalg.det(S) > 0
    assert np.max(np.abs(S - noisy)) < 1e-8
    assert not np.array_equal(S, noisy)
    # a reflection is never "already a rotation", whatever its orthonormality
    F = R @ np.diag([1.0, 1.0, -1.0])
    assert np.linalg.det(snap_to_rotation(F)) > 0
    assert ROTATION_EXACT_TOLERANCE == 1e-12
    np.testing.assert_allclose(np.linalg.norm(exact), 1.0, rtol=0, atol=4e-16)


def test_exact_norm_agrees_with_numpy():
    rng = np.random.default_rng(11)
    for _ in range(100):
        v = rng.normal(size=4) * 10.0 ** rng.integers(-5, 5)
        assert exact_norm(v) == pytest.approx(float(np.linalg.norm(v)), rel=4e-16)
