"""The query server: a helper thread that runs one nogil kernel (serve) and takes requests from
the solver's thread through an array of control words -- no GIL.

A request is answered in chunks that the server's thread and the poster claim as they come
(post_chunks, claim, chunk_done; the poster then answers what is left and waits only for the
chunks the server holds: SpinServer.help) -- the poster never waits for a late server. What a
chunk is depends on the job: a namedtuple of the arrays a request reads and writes, whose class
was registered with its work function (register_job; engine.collide.collider's RowsJob for the
drape's row queries, engine.collide.moving's TrackJob for the walk's). A point's answer depends
on its own rows alone, so the answers are the same whichever thread answers which chunk.

Between requests the kernel spins rather than sleeps (waking a sleeping thread costs as long as
the work it was woken for). A spinning helper takes a core that other work may want: a collider
lets its helper go when waits for the helper's chunks show it is not getting one (StallWatch),
and a collider made with helper=False never starts one. The kernel returns when ctl[STOP] is
set, or by itself after IDLE ticks (~0.1 s) without a request; the next request starts it again.
A wait for an answer is an error after WAIT seconds of a running kernel, or as soon as the
thread is dead; not while the kernel has not started (its first call may compile it).

    server = SpinServer("query-server")
    server.start(job)               # (again whenever the job's arrays change)
    server.post_chunks(n)           # ... the server's thread starts on it
    waited = server.help(job, HELP_WAIT)   # this thread answers what is left, waits for the rest
    server.close()
"""

from __future__ import annotations

import threading
import time
import weakref
from collections import deque
from queue import Queue

import numpy as np

from engine.errors import SimulationError
from engine.jit import (atomic_add, atomic_cas, atomic_load, atomic_store, cycle_counter, nbtypes, njit, overload,
                        serial_kernel, spin_pause)

REQ, DONE, STOP, RUNNING = range(4)  # control words; the kernels may use ctl[4:] for their own
# ... and a request answered in chunks (post_chunks; claim, chunk_done, wait_chunks): points the
# request asked the maps for, the chunks left to claim (claim_word: the request's number, the
# first and the end of the range not yet claimed), chunks finished, chunks in the request;
# chunks the server's thread answered, and the poster's (running counts)
ASKED, NEXT, FINISHED, N_CHUNKS, SERVER_CHUNKS, SOLVER_CHUNKS = 5, 6, 7, 8, 10, 11
WAIT = 30.0  # s: the longest wait for an answer before the server is taken as dead
IDLE = 3 * 10 ** 8  # time-stamp counter ticks (~0.1 s) without a request after which a kernel returns


@njit(cache=True, inline="always")
def serve_wait(ctl, last):
    """In a server kernel: spin until a request after `last` is posted and return its number, or
    return -1 (ctl[RUNNING] set to 0) on ctl[STOP] or after IDLE ticks without one."""
    since = cycle_counter()
    while True:
        r = atomic_load(ctl, REQ)
        if r != last:
            return r
        if atomic_load(ctl, STOP) != 0 or cycle_counter() - since > IDLE:
            atomic_store(ctl, RUNNING, 0)
            return -1
        spin_pause()


REQ_BITS = 15  # the request number's low bits in the claim word (a request is claimed only
# while it is the last one posted; the poster waits for each before posting another)
_CHUNK_MASK = (1 << 24) - 1


@njit(cache=True, inline="always")
def claim_word(r, first, end):
    """ctl[NEXT] for request r with chunks first .. end - 1 left to claim."""
    return ((r & ((1 << REQ_BITS) - 1)) << 48) | (first << 24) | end


@njit(cache=True, inline="always")
def claim(ctl, r, from_end=False):
    """A chunk of request r, claimed for this thread (either thread may call it at any time:
    ctl[NEXT] holds the range of chunks not yet claimed and is swapped for the range less this
    one, so each chunk goes to one thread, and a thread holding an older request's number
    claims nothing), or -1 when none is left. The first of the range, or with from_end the last:
    the walk's solver thread claims from the end and its query server from the start, so each
    keeps answering about the same points -- their rows stay in its core's cache instead of
    crossing to the other core at every request.
    Inlined into the servers' kernels (engine.collide.moving, engine.collide.collider): numba's
    on-disk cache checks a kernel against its own file only -- change those files with this."""
    while True:
        w = atomic_load(ctl, NEXT)
        first = (w >> 24) & _CHUNK_MASK
        end = w & _CHUNK_MASK
        if (w >> 48) != (r & ((1 << REQ_BITS) - 1)) or first >= end:
            return -1
        if from_end:
            if atomic_cas(ctl, NEXT, w, w - 1):
                return end - 1
        elif atomic_cas(ctl, NEXT, w, w + (1 << 24)):
            return first


@njit(cache=True, inline="always")
def chunk_done(ctl, tally, asked):
    """A claimed chunk answered: its asked points counted (ctl[ASKED]), one for the thread
    (ctl[tally]), and then -- last -- counted as finished."""
    atomic_add(ctl, ASKED, asked)
    ctl[tally] += 1
    atomic_add(ctl, FINISHED, 1)


@njit(cache=True, inline="always")
def wait_chunks(ctl, wait):
    """Spin until every chunk of the request is finished; returns the ticks it waited, or -1
    after `wait` ticks (a thread died holding one)."""
    since = cycle_counter()
    while atomic_load(ctl, FINISHED) < ctl[N_CHUNKS]:
        if cycle_counter() - since > wait:
            return -1
        spin_pause()
    return cycle_counter() - since


def answer_chunks(ctl, r, tally, job):
    """Inside a kernel: answer chunks of request r of `job` (claim: each chunk by one thread,
    counted in ctl[tally]) until none is left to claim. Each job class has its own work function
    (register_job)."""
    raise TypeError(f"no work function is registered for {type(job).__name__} (engine.collide.server.register_job)")


def register_job(cls: type, work) -> None:
    """Jobs of the namedtuple class `cls` are answered by the numba function work(ctl, r, tally,
    job) (serve, SpinServer.help)."""
    @overload(answer_chunks)
    def _answer(ctl, r, tally, job):
        if isinstance(job, nbtypes.BaseNamedTuple) and job.instance_class is cls:
            return lambda ctl, r, tally, job: work(ctl, r, tally, job)


@serial_kernel
def serve(ctl, job):
    """The server thread's kernel: takes chunks of each request as they are posted; returns on
    ctl[STOP], or after IDLE ticks without a request."""
    last = ctl[DONE]
    atomic_store(ctl, RUNNING, 2)
    while True:
        r = serve_wait(ctl, last)
        if r < 0:
            return
        last = r
        answer_chunks(ctl, r, SERVER_CHUNKS, job)
        atomic_store(ctl, DONE, r)


@serial_kernel
def answer_rest(ctl, wait, job):
    """The poster's thread: the chunks of the last request not yet claimed, then the wait for
    those the server holds; returns the ticks it waited, -1 when one was not finished within
    `wait` ticks."""
    answer_chunks(ctl, atomic_load(ctl, REQ), SOLVER_CHUNKS, job)
    return wait_chunks(ctl, wait)


STALL = 900_000  # time-stamp counter ticks (~0.3 ms): a wait for the helper's chunks this long is a stall
STALL_WINDOW = 100  # ... and when STALL_SHARE of the last this many shared requests stalled, the helper is let go
STALL_SHARE = 0.25
CPU_WINDOW = 0.25  # s of wall time: the solver's thread's share of a core is measured over this long ...
CPU_SHARE = 0.55  # ... and when it stayed under this for CPU_WINDOWS windows in a row, the helper is let go
CPU_WINDOWS = 3


class StallWatch:
    """Whether a collider's helper thread still pays: a wait for the chunks it holds longer than
    STALL means it was not running -- the machine's cores are busy with other work (other
    try-ons), and a helper then makes the solver wait for a core instead of saving it time.
    When STALL_SHARE of the last STALL_WINDOW shared requests stalled (a burst is not enough:
    a walk rendering its maps in a third thread stalls now and then), `lost` turns True and the
    collider answers alone from then on (the same answers). Stalls do not show every kind of
    crowding (two walks at once stall seldom), so the helper is also let go when the solver's
    thread got less than CPU_SHARE of a core in CPU_WINDOWS windows in a row."""

    def __init__(self):
        self.requests = self.stalls = 0
        self._recent: deque = deque(maxlen=STALL_WINDOW)
        self.lost = False
        self.low_windows = 0
        self._window = (time.perf_counter(), time.thread_time())

    def saw(self, waited: int) -> None:
        self.requests += 1
        stalled = waited > STALL
        self.stalls += stalled
        self._recent.append(stalled)
        if len(self._recent) == STALL_WINDOW and sum(self._recent) >= STALL_SHARE * STALL_WINDOW:
            self.lost = True
        now = time.perf_counter()
        if now - self._window[0] >= CPU_WINDOW:
            cpu = time.thread_time()
            share = (cpu - self._window[1]) / (now - self._window[0])
            self._window = (now, cpu)
            self.low_windows = self.low_windows + 1 if share < CPU_SHARE else 0
            if self.low_windows >= CPU_WINDOWS:
                self.lost = True


HELP_WAIT = 3 * 10 ** 10  # time-stamp counter ticks (~10 s): a chunk a helper holds not finished by then is lost


def after_help(waited: int, stalls: StallWatch | None) -> bool:
    """After the poster answered what was left of a request and waited for the helper's chunks
    (wait_chunks: the ticks it waited, or -1): an error when a chunk was lost (the helper's
    thread died holding it), else the wait goes to `stalls` (None: not watched); returns whether
    the helper is to be let go."""
    if waited < 0:
        raise SimulationError("the collision query server stopped answering (its thread died holding part of a "
                              "query); this is a bug -- please report it")
    if stalls is None:
        return False
    stalls.saw(waited)
    return stalls.lost


def helper_default() -> bool:
    """Whether colliders share their queries with a helper thread unless told (the environment's
    TRYON_QUERY_HELPER=0 turns it off: a machine running as many try-ons at once as it has cores
    has no idle core for the helpers to spin on)."""
    from engine.settings import current

    return current().query_helper


def _thread(jobs: Queue) -> None:
    """The server's thread: one kernel call per job, until None."""
    while True:
        job = jobs.get()
        if job is None:
            return
        kernel, args = job
        kernel(*args)


def _end(ctl: np.ndarray, jobs: Queue) -> None:
    ctl[STOP] = 1
    jobs.put(None)


class SpinServer:
    """The thread and its control words (ctl: int64, 16 words; par: float64 parameters for the
    kernel). The thread starts with the first start(); close() -- or dropping the server --
    ends it."""

    def __init__(self, name: str):
        self.name = name
        self.ctl = np.zeros(16, np.int64)
        self.par = np.zeros(16)
        self._req = 0
        self._thread: threading.Thread | None = None
        self._jobs: Queue | None = None
        self._args = None

    def running_on(self, job: tuple) -> bool:
        """Whether the kernel runs (or is about to) on this job (the same tuple object)."""
        return bool(self.ctl[RUNNING]) and self._args is job

    def start(self, job: tuple) -> None:
        """Run serve(ctl, job) in the thread (stopping the one running)."""
        self.stop()
        if self._thread is None:
            self._jobs = Queue()
            self._thread = threading.Thread(target=_thread, args=(self._jobs,), name=self.name, daemon=True)
            self._thread.start()
            self._final = weakref.finalize(self, _end, self.ctl, self._jobs)
        self.ctl[DONE] = self._req  # (nothing pending)
        self._args = job
        self._launch()

    def _launch(self) -> None:
        self.ctl[RUNNING] = 1
        self._jobs.put((serve, (self.ctl, self._args)))

    def help(self, job: tuple, wait: int) -> int:
        """Answer what the server's thread has not claimed of the last request, then wait for the
        chunks it holds: the ticks waited, or -1 after `wait` ticks (see after_help)."""
        return int(answer_rest(self.ctl, wait, job))

    @property
    def next_request(self) -> int:
        """The number request() will post next (a kernel may tag its own words with it)."""
        return self._req + 1

    def request(self, launch: bool = True) -> None:
        """Post a request (the arrays and par hold what it asks; the kernel reads ctl[REQ] last).
        launch False: the kernel is not (re)started for it (the poster answers it itself)."""
        if launch and not self.ctl[RUNNING]:  # it returned after a while without requests: again
            self._launch()
        self._req += 1
        self.ctl[REQ] = self._req  # (numpy's stores are in program order)

    def post_chunks(self, n_chunks: int, launch: bool = True) -> None:
        """Post a request answered in n_chunks chunks (claim): the kernel's own words and par
        first, then this (the chunk count after the claim word: see claim)."""
        ctl = self.ctl
        ctl[NEXT] = claim_word(self.next_request, 0, n_chunks)
        ctl[FINISHED] = ctl[ASKED] = 0
        ctl[N_CHUNKS] = n_chunks
        self.request(launch)

    def wait(self) -> None:
        """Wait for the last request's answer (a dead or stuck server is an error, not a hang)."""
        self._spin(DONE, self._req)

    def _spin(self, word: int, value: int) -> None:
        ctl = self.ctl
        if ctl[word] == value:
            return
        deadline = time.perf_counter() + WAIT
        n = 0
        while ctl[word] != value:
            n += 1
            if word == DONE and not ctl[RUNNING] and ctl[DONE] != value:
                self._launch()  # it gave up waiting just before the request came: again (it answers it)
            if ctl[RUNNING] == 1:  # started, not yet spinning (its first call compiles it): no deadline yet
                deadline = time.perf_counter() + WAIT
            if n % 4096 == 0 and (not self._thread.is_alive() or time.perf_counter() > deadline):
                raise SimulationError(f"the collision {self.name.replace('-', ' ')} stopped answering (its thread "
                                      f"{'ended' if not self._thread.is_alive() else 'is stuck'}); "
                                      "this is a bug -- please report it")

    def stop(self) -> None:
        """Stop the kernel (after it answered what was asked)."""
        if self._args is None:
            return
        if not self._thread.is_alive():  # (it died: an error said so already)
            self._args = None
            return
        try:
            self.wait()
        except SimulationError:
            if self._thread.is_alive():
                raise
            # it died while this waited (a kernel that raised is still "alive" while its
            # traceback prints): what it held was answered or reported by the poster's wait
            # for its chunks (wait_chunks), so there is nothing to wait for
            self._args = None
            return
        if self.ctl[RUNNING]:
            self.ctl[STOP] = 1
            self._spin(RUNNING, 0)
            self.ctl[STOP] = 0
        self._args = None

    def close(self) -> None:
        """Stop the kernel and end the thread."""
        self.stop()
        if self._thread is not None:
            self._final()
            self._thread.join()
            self._thread = None
            self.ctl[STOP] = 0  # (a server started later runs)
