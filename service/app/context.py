"""The application of one process: every use case wired to the settings, the map store and each
other, for the front ends (the HTTP API and the CLI) to call.

``App.create(settings)`` opens the store (migrated; the demo Chess map seeded as
``settings.default_map_id`` when configured and absent), the map loader, the localizer, the
session and build services. ``close()`` releases them. A front end holds one ``App`` and calls
only its services: ``app.maps``, ``app.localizer``, ``app.sessions``, ``app.builds``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from quadloc.factors.pose_residuals import compile_kernels
from quadloc.maps.cache import CompiledMapCache
from quadloc.maps.store import MapStore
from quadloc.service.app.builds import BuildService
from quadloc.service.app.calibrations import CalibrationService
from quadloc.service.app.localization import Localizer, SolveObserver
from quadloc.service.app.map_loader import MapLoader
from quadloc.service.app.maps import MapService
from quadloc.service.app.sessions import SessionService
from quadloc.service.localization.constellations import compile_place_kernels
from quadloc.service.localization.search import compile_search_kernels
from quadloc.service.settings import Settings

__all__ = ["App"]

log = logging.getLogger("quadloc.app")


@dataclass
class App:
    """The use cases of one process (module docstring)."""

    settings: Settings
    store: MapStore
    maps: MapService
    map_loader: MapLoader
    localizer: Localizer
    sessions: SessionService
    builds: BuildService
    calibrations: CalibrationService

    @classmethod
    def create(cls, settings: Settings, *, store: MapStore | None = None,
               observer: SolveObserver | None = None) -> App:
        """The application for ``settings`` (``store`` overrides the database URL;
        ``observer`` receives the localization outcomes, e.g. the HTTP layer's metrics)."""
        if store is None:
            store = MapStore(settings.effective_database_url,
                             cache=CompiledMapCache(settings.map_cache_ttl_s))
        maps = MapService(store, settings)
        if maps.seed_demo():
            log.info("seeded the demo Chess map as %r", settings.default_map_id)
        loader = MapLoader(store, settings.solve_time_budget_ms / 1e3)
        calibrations = CalibrationService(store)
        localizer = Localizer(settings, loader, observer, calibrations.constants_of)
        builds = BuildService(store, maps, settings)
        builds.sweep_stale()
        return cls(settings=settings, store=store, maps=maps, map_loader=loader,
                   localizer=localizer, sessions=SessionService(settings, loader,
                                                                localizer.slots,
                                                                calibrations.constants_of),
                   builds=builds, calibrations=calibrations)

    def start(self) -> None:
        """Serve (again, after :meth:`close`): session frames and builds run."""
        self.sessions.close(stop=False)
        self.builds.stop_running(stop=False)

    @staticmethod
    def warm_up() -> None:
        """Compile (or load from their cache) the numeric kernels of the solvers, so that no
        request's time budget pays for it (numba; ~13 s the first time on a machine, < 1 s
        from the cache: docs/design/factors.md), the RANSAC and place searches' included."""
        compile_kernels()
        compile_place_kernels()
        compile_search_kernels()

    def close(self) -> None:
        """The process is stopping: session frames and builds in progress stop at their next
        check (answered ``time_budget_exceeded`` / marked ``runner_lost``), the map loader's
        threads stop and the store's connections close."""
        self.sessions.close()
        self.builds.stop_running()
        self.map_loader.close()
        self.store.close()
