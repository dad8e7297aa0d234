"""When a cloth solver checks collisions: every `every` steps. A whole `every` checks at the
iterations it divides; a fractional one (the walk's: as often as the body's travel asks, not
rounded down to whole steps) at start + ceil(k * every), k = 0, 1, ..., start being the iteration
it was first used at -- checks `every` steps apart on average, floor or ceil of it each."""

from __future__ import annotations

import math


class CheckSchedule:
    def __init__(self):
        self._frac = None  # a fractional spacing's [every, start, k, next check]

    def now(self, every: float, iteration: int) -> int:
        """Whether iteration checks: 0 if not, else the steps until the next check (how far
        ahead the points are predicted)."""
        e = float(every)
        if e.is_integer():
            return int(e) if iteration % int(e) == 0 else 0
        f = self._frac
        if f is None or f[0] != e:
            f = self._frac = [e, iteration, 0, iteration]
        if iteration < f[3]:
            return 0
        f[2] += 1
        f[3] = f[1] + math.ceil(f[2] * e - 1e-9)
        return f[3] - iteration

    def next(self, every: float, iteration: int) -> tuple[int, int] | None:
        """(iteration of the next check, how many steps ahead it will look), as now() will have
        them; None if not known yet."""
        e = float(every)
        if e.is_integer():
            e = int(e)
            return -(-iteration // e) * e, e
        f = self._frac
        if f is None or f[0] != e:
            return None
        return f[3], f[1] + math.ceil((f[2] + 1) * e - 1e-9) - f[3]

    def due(self, every: float, iteration: int) -> bool:
        """Whether iteration checks (now() without moving the schedule on)."""
        e = float(every)
        if e.is_integer():
            return iteration % int(e) == 0
        f = self._frac
        return f is None or f[0] != e or iteration >= f[3]
