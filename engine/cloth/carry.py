"""A collider's answers carried between queries. Asking the collider is the costliest part of a
step, and at the eq. 4 time step a point moves a fraction of a millimetre a step, so the last
answer is carried forward (its depth corrected for the move along the normal,
kernels_carry.stale_contacts) until a point moved `requery_move` since the last query, a clear
point moved as far as it was from the band, `requery_every` steps passed, or the body changed
(the collider's version). A collider that answers rows (Collider.answers_rows) is then asked only
for the points whose answer may have changed (those in contact, and clear points that moved as
far as their distance from the band); between two such queries a clear point that may have
reached the band is asked alone. A collider whose body moves every step (solver_carries False) is
asked every time."""

from __future__ import annotations

import numpy as np

from engine.cloth import kernels_carry as KR
from engine.cloth.config import StepConfig
from engine.collide.base import Answer, Collider


class CarriedAnswers:
    """The last answers of `collider` for m checked points (tolerance: the collision band's, m)."""

    def __init__(self, collider: Collider, config: StepConfig, m: int, tolerance: float):
        self.collider, self.config, self.tolerance = collider, config, tolerance
        self.by_rows = collider.answers_rows
        self.ask_rows = np.zeros(m, dtype=np.int64)  # points to ask the collider alone
        self._no_rows = np.zeros(0, dtype=np.int64)
        self._q = None  # (points asked, points at the last query of all, status, normal, body v, depth,
        # carried status, carried depth)
        self._age, self._version = 0, None

    def answer(self, points: np.ndarray) -> Answer:
        """The collider's answer for `points`, carried or asked."""
        cfg, c = self.config, self.collider
        q = self._q
        if q is not None and c.version == self._version:
            q_pts, g_pts, q_st, q_n, q_bv, q_d, st, d = q
            # a point asked alone is asked as soon as it may touch the band (contacts are never missed)
            reach, slack = cfg.requery_move, (0.0 if self.by_rows else 0.1 * self.tolerance)
            if self._age < cfg.requery_every:
                k = KR.stale_contacts(points, q_pts, g_pts, q_st, q_n, q_d, st, d, reach, slack,
                                      self.ask_rows if self.by_rows else self._no_rows, c.depth_along_z)
                if k >= 0:  # the contacts' answers carry; clear points that may not be clear ask alone
                    self._age += 1
                    if k > 0:
                        self._ask_rows(points, k)
                    return st, q_n, q_bv, d
            if self.by_rows:
                self._ask_rows(points, KR.rows_to_ask(points, q_pts, q_st, q_d, reach, slack, self.ask_rows))
                g_pts[:] = points
                self._age = 1
                return st, q_n, q_bv, d
        status, normal, bvel, depth = c.query(points)
        if cfg.requery_every > 1 and c.solver_carries:
            self._q = (points.copy(), points.copy(), status.copy(), normal.copy(), bvel.copy(), depth.copy(),
                       status.copy(), depth.copy())
        self._age, self._version = 1, c.version
        return status, normal, bvel, depth

    def _ask_rows(self, points: np.ndarray, k: int) -> None:
        """Ask the collider for points[ask_rows[:k]] alone; keep their answers."""
        q_pts, _, q_st, q_n, q_bv, q_d, st, d = self._q
        status, normal, bvel, depth = self.collider.query_rows(points, self.ask_rows, k)
        KR.keep_rows(self.ask_rows, k, points, status, normal, bvel, depth, q_pts, q_st, q_n, q_bv, q_d, st, d)
