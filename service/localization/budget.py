"""What a solve budget counts: CPU time of the solving thread, plus a wall-clock hard limit.

``LocalizationOptions.time_budget_ms`` is a budget of CPU time of the thread that runs the
solve (``time.thread_time()``); every :class:`Deadline` also has a wall-clock hard limit of
:data:`WALL_LIMIT_FACTOR` x the budget (the latency guarantee). A bare ``float`` is accepted
everywhere a deadline is (a ``time.perf_counter()`` instant: wall clock only). Why (issue 14,
part 4): ``docs/design/localization.md``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

__all__ = ["WALL_LIMIT_FACTOR", "Deadline", "as_deadline", "deadline_passed", "earliest"]

#: Wall-clock hard limit of a solve, as a multiple of its CPU budget.
WALL_LIMIT_FACTOR = 2.0


@dataclass(frozen=True)
class Deadline:
    """A stop instant on two clocks: ``cpu`` (``time.thread_time()`` of the solving thread,
    seconds; ``inf`` = none) and ``wall`` (``time.perf_counter()``, seconds; ``inf`` = none).
    It has passed when either has. Only meaningful in the thread that created it (the CPU
    clock is per thread).

    ``cpu_check_from`` (a ``time.perf_counter()`` instant, ``-inf`` = always) is when the CPU
    stop can first have been reached: a thread's CPU time grows no faster than wall time, so
    before that instant :meth:`passed` reads only the cheap wall clock (``time.thread_time()``
    is a system call, ~2.4 us against ~0.2 us here, and the search checks its deadline often).
    """

    cpu: float = math.inf
    wall: float = math.inf
    cpu_check_from: float = -math.inf

    @classmethod
    def after(cls, budget_ms: float | None, factor: float = 1.0, *,
              cpu_start: float | None = None, wall_start: float | None = None
              ) -> Deadline | None:
        """The deadline ``factor x budget_ms`` of CPU time after ``cpu_start`` (default: now,
        this thread) with the wall-clock hard limit ``WALL_LIMIT_FACTOR x factor x budget_ms``
        after ``wall_start`` (default: now); None without a budget."""
        if budget_ms is None:
            return None
        cpu_now, wall_now = time.thread_time(), time.perf_counter()
        cpu0 = cpu_now if cpu_start is None else cpu_start
        wall0 = wall_now if wall_start is None else wall_start
        budget_s = factor * float(budget_ms) / 1e3
        cpu_stop = cpu0 + budget_s
        return cls(cpu_stop, wall0 + WALL_LIMIT_FACTOR * budget_s,
                   wall_now + (cpu_stop - cpu_now))

    def passed(self) -> bool:
        """Whether either clock is past its stop."""
        wall = time.perf_counter()
        if wall > self.wall:
            return True
        return wall >= self.cpu_check_from and time.thread_time() > self.cpu


def as_deadline(deadline: Deadline | float | None) -> Deadline | None:
    """``deadline`` as a :class:`Deadline` (a float is a ``time.perf_counter()`` instant)."""
    if deadline is None or isinstance(deadline, Deadline):
        return deadline
    return Deadline(math.inf, float(deadline))


def deadline_passed(deadline: Deadline | float | None) -> bool:
    """Whether ``deadline`` (a :class:`Deadline`, a ``time.perf_counter()`` instant, or None =
    never) has passed."""
    return deadline is not None and as_deadline(deadline).passed()


def earliest(a: Deadline | float | None, b: Deadline | float | None) -> Deadline | None:
    """The deadline that passes as soon as either ``a`` or ``b`` has (None = never)."""
    da, db = as_deadline(a), as_deadline(b)
    if da is None or db is None:
        return da if db is None else db
    return Deadline(min(da.cpu, db.cpu), min(da.wall, db.wall),
                    min(da.cpu_check_from, db.cpu_check_from))
