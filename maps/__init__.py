"""Ellipsoid maps: the model and its JSON format (``maps.model``), solver arrays
(``maps.compiled``), versioned storage on SQLite / PostgreSQL (``maps.store``), the Chess demo
map (``maps.demo``) and reconstruction of ellipsoids from multi-view ellipses
(``maps.reconstruct``)."""

from maps.compiled import CompiledMap, compile_map
from maps.model import MapObject, MapValidationError, SceneMap

__all__ = ["CompiledMap", "MapObject", "MapValidationError", "SceneMap", "compile_map"]
