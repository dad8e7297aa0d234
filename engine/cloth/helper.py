"""The step helper: a thread on the machine's other core that takes half of each force pass.

The force pass (engine.cloth.kernels.eval_forces_and_integrate) cuts the springs in two parts
and posts part B through a few control words; the helper's kernel (K.force_helper) spins on
them without the GIL, claims part B and computes it while the solver's thread computes part A.
Part B has its own sums, added afterwards, and whichever thread claims it first computes it: the
result is the same bit for bit whichever thread did it, and the solver never waits for a helper
that is busy, descheduled or not started (it then does part B itself). A solver without a
helper sums all springs in one pass (part B empty): in another order, so its results differ
from a helper's in the last bits.

Why a spinning kernel: waking a sleeping thread took ~0.25 ms here (median; the walking query
server measured it, engine.collide.moving), longer than the part. The kernel returns after
~0.1 s without a request (K.HELPER_IDLE; a solver that stopped stepping), and the next step
starts it again. The thread ends when the solver is dropped (a finalizer) or closed.

Not used when the machine gives this process one core, when TRYON_STEP_HELPER=0, or when the
collider runs a thread of its own on the other core (the walk's query server,
engine.collide.moving.TrackCollider.prefetch): two threads spinning on one core would take
turns and each would wait for the other.
"""

from __future__ import annotations

import os
import threading
import weakref
from queue import Queue

import numpy as np

from engine.cloth import kernels as K

HELPER_SHARE = 0.55  # part B's share of each spring group (the solver's thread also copies, adds and integrates)


def helper_wanted() -> bool:
    """Whether a step helper may run: two or more cores for this process, not switched off."""
    if os.environ.get("TRYON_STEP_HELPER", "1") == "0":
        return False
    try:
        return len(os.sched_getaffinity(0)) >= 2
    except AttributeError:  # (not Linux)
        return (os.cpu_count() or 1) >= 2


def force_split(runs, share: float = HELPER_SHARE) -> np.ndarray:
    """(4,) int64: where the force pass cuts each group (engine.cloth.model.SpringRuns) into
    parts A and B -- the fast group's runs and single springs, then the slow group's -- so that
    part B holds about `share` of each group's springs (0: none)."""
    def cut(r_lo: int, r_hi: int, s_lo: int, s_hi: int) -> tuple[int, int]:
        if share <= 0.0:
            return r_hi, s_hi
        lens = runs.runs[r_lo:r_hi, 3]
        total = int(lens.sum())
        keep = np.cumsum(lens)
        r = r_lo + int(np.searchsorted(keep, (1.0 - share) * total)) if total else r_lo
        s = s_lo + int(round((1.0 - share) * (s_hi - s_lo)))
        return min(r, r_hi), min(s, s_hi)

    r_fast, n_fast, n_all = runs.r_fast, runs.n_fast, len(runs.perm)
    fa = cut(0, r_fast, runs.n_run, n_fast)
    sl = cut(r_fast, len(runs.runs), n_fast + runs.n_run_slow, n_all)
    return np.array([fa[0], fa[1], sl[0], sl[1]], np.int64)


def _helper_thread(jobs: Queue) -> None:
    while True:
        args = jobs.get()
        if args is None:
            return
        K.force_helper(*args)


def _end(ctl: np.ndarray, jobs: Queue) -> None:
    ctl[K.H_STOP] = 1
    jobs.put(None)


class StepHelper:
    """The helper thread of one solver: ctl (its control words), start(args) before each force
    pass (starts the kernel when it is not running on these arrays), stop(), close()."""

    def __init__(self):
        self.ctl = np.zeros(8, np.int64)
        self._args = None
        self._jobs: Queue = Queue()
        self._thread = threading.Thread(target=_helper_thread, args=(self._jobs,), name="step-helper", daemon=True)
        self._thread.start()
        self._final = weakref.finalize(self, _end, self.ctl, self._jobs)

    def start(self, args: tuple) -> None:
        """Have the kernel run on `args` (K.force_helper's after hctl; the same tuple object
        while nothing changed)."""
        if self.ctl[K.H_RUNNING] and self._args is args:
            return
        self.stop()
        self._args = args
        self.ctl[K.H_RUNNING] = 1
        self._jobs.put((self.ctl, *args))

    def stop(self) -> None:
        """Stop the kernel (it finishes a part it claimed first)."""
        if self.ctl[K.H_RUNNING]:
            self.ctl[K.H_STOP] = 1
            while self.ctl[K.H_RUNNING]:
                if not self._thread.is_alive():
                    break
            self.ctl[K.H_STOP] = 0
            self.ctl[K.H_RUNNING] = 0

    def close(self) -> None:
        """End the thread."""
        self.stop()
        self._final()
        self._thread.join()
