"""The time budget of an iterative computation: a :class:`Deadline` after which it stops.

One type for every budget of the code base, checked between the steps of a computation (RANSAC
batches, LM iterations, map-build labels): a stop instant on the wall clock
(``time.perf_counter()``) and, for a solve, on the CPU clock of the solving thread
(``time.thread_time()``). ``None`` where a ``Deadline | None`` is expected means no limit.
Constructors: :meth:`Deadline.cpu_budget` (CPU time of the calling thread with a wall-clock hard
limit of :data:`WALL_LIMIT_FACTOR` x the budget: a ``localize()`` solve, a session frame or
request) and :meth:`Deadline.wall_budget` (wall-clock time only: a map build, a localize
batch). Why a solve counts CPU time: ``docs/design/localization.md``, "The solve budget". A
deadline may also carry cancellation events (:meth:`Deadline.cancelled_by`): it has passed once
any is set (the client went away, the server is stopping).
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, replace
from typing import overload

__all__ = ["WALL_LIMIT_FACTOR", "Deadline", "deadline_passed", "earliest"]

#: Wall-clock hard limit of a CPU-time budget (:meth:`Deadline.cpu_budget`), as a multiple of
#: the budget.
WALL_LIMIT_FACTOR = 2.0


@dataclass(frozen=True)
class Deadline:
    """A stop instant on two clocks: ``cpu`` (``time.thread_time()`` of the solving thread,
    seconds; ``inf`` = none) and ``wall`` (``time.perf_counter()``, seconds; ``inf`` = none).
    It has passed when either has. Only meaningful in the thread that created it (the CPU
    clock is per thread).

    ``cpu_check_from`` (a ``time.perf_counter()`` instant; ``-inf`` = always, ``inf`` = never)
    is when the CPU stop can first have been reached: a thread's CPU time grows no faster than
    wall time, so before that instant :meth:`passed` reads only the cheap wall clock
    (``time.thread_time()`` is a system call, ~2.4 us against ~0.2 us here, and the search
    checks its deadline often).
    """

    cpu: float = math.inf
    wall: float = math.inf
    cpu_check_from: float = -math.inf
    cancel: tuple[threading.Event, ...] = ()

    @overload
    @classmethod
    def cpu_budget(cls, budget_ms: float, factor: float = 1.0, *,
                   cpu_start: float | None = None, wall_start: float | None = None
                   ) -> Deadline: ...

    @overload
    @classmethod
    def cpu_budget(cls, budget_ms: None, factor: float = 1.0, *,
                   cpu_start: float | None = None, wall_start: float | None = None
                   ) -> None: ...

    @classmethod
    def cpu_budget(cls, budget_ms: float | None, factor: float = 1.0, *,
                   cpu_start: float | None = None, wall_start: float | None = None
                   ) -> Deadline | None:
        """The deadline ``factor x budget_ms`` (milliseconds) of CPU time of this thread after
        ``cpu_start`` (a ``time.thread_time()`` instant, s; default: now) with the wall-clock
        hard limit ``WALL_LIMIT_FACTOR x factor x budget_ms`` after ``wall_start`` (a
        ``time.perf_counter()`` instant, s; default: now); None without a budget."""
        if budget_ms is None:
            return None
        cpu_now, wall_now = time.thread_time(), time.perf_counter()
        cpu0 = cpu_now if cpu_start is None else cpu_start
        wall0 = wall_now if wall_start is None else wall_start
        budget_s = factor * float(budget_ms) / 1e3
        cpu_stop = cpu0 + budget_s
        return cls(cpu_stop, wall0 + WALL_LIMIT_FACTOR * budget_s,
                   wall_now + (cpu_stop - cpu_now))

    @classmethod
    def wall_budget(cls, budget_s: float, *, start: float | None = None) -> Deadline:
        """The deadline ``budget_s`` seconds of wall-clock time after ``start`` (a
        ``time.perf_counter()`` instant, s; default: now), whatever CPU time is spent (the CPU
        clock is never read)."""
        wall0 = time.perf_counter() if start is None else start
        return cls(wall=wall0 + float(budget_s), cpu_check_from=math.inf)

    def cancelled_by(self, *events: threading.Event) -> Deadline:
        """This deadline, passed as well once any of ``events`` is set."""
        return replace(self, cancel=self.cancel + events)

    def remaining_cpu_s(self) -> float:
        """CPU seconds of this thread left before the CPU stop (negative once past; ``inf``
        without one)."""
        return self.cpu - time.thread_time() if math.isfinite(self.cpu) else math.inf

    def remaining_wall_s(self) -> float:
        """Wall-clock seconds left before the wall stop (negative once past; ``inf`` without
        one)."""
        return self.wall - time.perf_counter()

    def passed(self) -> bool:
        """Whether either clock is past its stop, or a cancellation event is set."""
        if any(event.is_set() for event in self.cancel):
            return True
        wall = time.perf_counter()
        if wall > self.wall:
            return True
        return wall >= self.cpu_check_from and time.thread_time() > self.cpu


def deadline_passed(deadline: Deadline | None) -> bool:
    """Whether ``deadline`` (None = never) has passed."""
    return deadline is not None and deadline.passed()


def earliest(a: Deadline | None, b: Deadline | None) -> Deadline | None:
    """The deadline that passes as soon as either ``a`` or ``b`` has (None = never)."""
    if a is None or b is None:
        return a if b is None else b
    return Deadline(min(a.cpu, b.cpu), min(a.wall, b.wall),
                    min(a.cpu_check_from, b.cpu_check_from), a.cancel + b.cancel)
