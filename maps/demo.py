"""The demo map shipped with QuadLoc: the 7-Scenes Chess ellipsoid map (11 objects, 7 categories).

``maps/data/chess.json`` is in the documented map format (``docs/maps.md``). Provenance (also in
the map's ``metadata.provenance``): converted by :func:`quadloc.maps.model.scene_map_from_chess`
from the project's reference file ``chess_scene.json``, the ellipsoidal model of the 7-Scenes Chess
scene used in the paper's 6-DoF experiments (Zins, Simon, Berger, "Level Set-Based Camera Pose
Estimation From Multiple 2D/3D Ellipse-Ellipsoid Correspondences"). World frame: 7-Scenes Chess
re-oriented with +Z up, metres.
"""

from __future__ import annotations

from pathlib import Path

from quadloc.maps.model import SceneMap

__all__ = ["DEMO_MAP_ID", "DEMO_MAP_PATH", "load_demo_map"]

DEMO_MAP_ID = "chess"
DEMO_MAP_PATH = Path(__file__).resolve().parent / "data" / "chess.json"


def load_demo_map() -> SceneMap:
    """The Chess demo map (id ``"chess"``, version 1, +Z up)."""
    return SceneMap.from_json(DEMO_MAP_PATH.read_text(encoding="utf-8"))
