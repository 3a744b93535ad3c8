"""Hostile inputs of issue 32 (tests and ``bench/adversarial.py``): recordings whose map build
once took gigabytes, and tracking-session requests that once ran for minutes.

Everything is seeded: the same arguments give the same document.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from quadloc.factors.camera import Camera
from quadloc.factors.rotations import pose_matrix
from quadloc.maps.building.recording import recording_to_dict

__all__ = ["HOSTILE_CAMERA", "grid_map", "grid_pose", "hostile_recording", "look_at"]

#: The camera of the hostile recordings (VGA).
HOSTILE_CAMERA = Camera(500.0, 500.0, 320.0, 240.0, 640, 480)


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``world_from_camera`` (4x4, OpenCV axes: z forward, y down) of a camera at ``eye`` (m)
    looking at ``target`` (m), world z up."""
    z = target - eye
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(z, x)
    return pose_matrix(np.column_stack([x, y, z]), eye)


def hostile_recording(n_frames: int = 2000, per_frame: int = 10, n_box: int = 9,
                      seed: int = 0, layout: str = "ring") -> dict[str, Any]:
    """The repro of issue 32, item 1: ``n_frames`` frames of ``per_frame`` random ellipses
    each, ``n_box`` of them labelled ``Box`` (the rest ``Chair``), no track ids.

    ``layout``: ``"ring"`` (cameras on a 3 m circle, 1.5 m high, all looking at the room's
    centre: every pair of rays from two frames nearly meets there, the worst case of the
    association) or ``"random"`` (random positions in a 6 m room looking at random points).
    """
    rng = np.random.default_rng([seed, 32])
    cam = HOSTILE_CAMERA
    frames = []
    for f in range(n_frames):
        if layout == "ring":
            a = 2 * np.pi * f / n_frames
            eye = np.array([3 * np.cos(a), 3 * np.sin(a), 1.5])
            target = rng.normal(0.0, 0.05, 3) + np.array([0.0, 0.0, 1.0])
        elif layout == "random":
            eye = rng.uniform([-3, -3, 0.5], [3, 3, 2.5])
            target = rng.uniform([-3, -3, 0], [3, 3, 2])
        else:
            raise ValueError(f"layout must be 'ring' or 'random', got {layout!r}")
        dets = []
        for k in range(per_frame):
            a_px = float(rng.uniform(8, 120))
            dets.append({"label": "Box" if k < n_box else "Chair",
                         "ellipse": {"cx": float(rng.uniform(20, cam.width - 20)),
                                     "cy": float(rng.uniform(20, cam.height - 20)),
                                     "a": a_px, "b": float(a_px * rng.uniform(0.3, 1.0)),
                                     "angle": float(rng.uniform(-1.5, 1.5))}})
        frames.append((f"f{f}", look_at(eye, target), dets))
    doc = recording_to_dict(cam, frames, name="hostile")
    for fr in doc["frames"]:  # rounded (0.1 px, 1e-7, 0.1 mm): 2,000 x 10 fit in 2 MB
        pose = fr["world_from_camera"]
        pose["quaternion_wxyz"] = [round(x, 7) for x in pose["quaternion_wxyz"]]
        pose["translation_m"] = [round(x, 4) for x in pose["translation_m"]]
        for det in fr["detections"]:
            det["ellipse"] = {k: round(v, 1) for k, v in det["ellipse"].items()}
    return doc


def grid_map(map_id: str = "grid", side: int = 16, n_labels: int = 8) -> dict[str, Any]:
    """A map document of ``side`` x ``side`` small ellipsoids on a wall 5 m in front of
    :func:`grid_pose` (labels ``L0..`` in turn): every object visible and separate in the image,
    so a session on it tracks with ``side**2`` associated detections per frame (the most
    the schema allows at 16 x 16)."""
    objects = []
    for i in range(side):
        for j in range(side):
            k = i * side + j
            objects.append({"object_id": f"o{k}", "category": f"L{k % n_labels}",
                            "center": [round((i - (side - 1) / 2) * 0.35, 4),
                                       5.0 + 0.3 * ((i + j) % 3),
                                       round((j - (side - 1) / 2) * 0.26, 4)],
                            "axes": [0.08, 0.1, 0.07]})
    return {"map_id": map_id, "name": "grid", "up_axis": [0.0, 0.0, 1.0],
            "categories": [f"L{i}" for i in range(n_labels)], "objects": objects}


def grid_pose(frame: int) -> np.ndarray:
    """``world_from_camera`` of frame ``frame`` of a slow walk (2 mm per frame along x) facing
    the wall of :func:`grid_map`."""
    eye = np.array([0.002 * frame, 0.0, 0.0])
    return look_at(eye, eye + np.array([0.0, 1.0, 0.0]))
