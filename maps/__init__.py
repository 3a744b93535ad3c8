"""Ellipsoid maps: the model and its JSON format (``quadloc.maps.model``), solver arrays
(``quadloc.maps.compiled``), versioned storage on SQLite / PostgreSQL (``quadloc.maps.store``), the
Chess demo map (``quadloc.maps.demo``) and reconstruction of ellipsoids from multi-view ellipses
(``quadloc.maps.reconstruct``)."""

from quadloc.maps.compiled import CompiledMap, compile_map
from quadloc.maps.model import MapObject, MapValidationError, SceneMap

__all__ = ["CompiledMap", "MapObject", "MapValidationError", "SceneMap", "compile_map"]
