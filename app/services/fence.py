"""Untrusted files are read in a child process with limits on memory (RLIMIT_AS), CPU time
(RLIMIT_CPU) and wall time, never in the API process and never on its event loop.

Why a child process rather than checks before every allocation: the readers are libraries
(trimesh, ezdxf, NumPy, SciPy, MeshFix) whose allocations and loops we do not see; a limit the
kernel enforces bounds all of them, a crash in native code ends only the child, and a reader
that hangs is killed. The children are forked from a forkserver that has the readers imported
(a child starts in ~15 ms), never from the API process (which may hold threads).

    result = await fenced(read_body, path, fps, settings=s, limits=lim)
"""

from __future__ import annotations

import asyncio
import multiprocessing as mp
import os
import resource
import signal
import threading
from dataclasses import dataclass

from fastapi import HTTPException

PRELOAD = ["engine.body.load", "engine.body.animation", "engine.body.gltf_anim", "engine.body.measure",
           "engine.body.fit", "engine.pattern.io", "engine.pattern.validate", "engine.pattern.dxf",
           "app.services.readers"]
_ctx_lock = threading.Lock()
_ctx = None


@dataclass(frozen=True)
class Limits:
    seconds: float = 60.0     # wall and CPU time of one read
    memory_mb: int = 2048     # address space a read may add to the loaded reader


def _context():
    global _ctx
    with _ctx_lock:
        if _ctx is None:
            _ctx = mp.get_context("forkserver")
            _ctx.set_forkserver_preload(PRELOAD)
        return _ctx


def _vm_size() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 0


def _child(conn, fn, args, settings, limits: Limits) -> None:
    """In the child: limits on, settings in, the result (or the reason) sent back."""
    from engine.errors import TryonError
    from engine.settings import use

    os.nice(5)  # the API's answers first
    cpu = max(1, int(limits.seconds))
    resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))
    cap = _vm_size() + limits.memory_mb * 2 ** 20
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    use(settings)
    try:
        msg = ("ok", fn(*args))
    except TryonError as e:
        msg = ("input", str(e))
    except MemoryError:
        msg = ("memory", "")
    except BaseException as e:  # noqa: BLE001 -- a reader's bug: reported, the service goes on
        msg = ("bug", f"{type(e).__name__}: {str(e).splitlines()[0][:200] if str(e) else ''}")
    conn.send(msg)
    conn.close()


async def _wait_readable(fd: int, seconds: float) -> bool:
    loop = asyncio.get_running_loop()
    ready = asyncio.Event()
    loop.add_reader(fd, ready.set)
    try:
        await asyncio.wait_for(ready.wait(), seconds)
        return True
    except asyncio.TimeoutError:
        return False
    finally:
        loop.remove_reader(fd)


async def fenced(fn, *args, settings, limits: Limits, what: str = "the file"):
    """fn(*args) in a limited child process; the project's errors become 400, the limits 413/400."""
    ctx = _context()
    recv, send = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_child, args=(send, fn, args, settings, limits), daemon=True)
    await asyncio.get_running_loop().run_in_executor(None, p.start)  # the forkserver's start may block
    send.close()  # the child holds the write end: its death reads as end-of-file
    kind, value = "time", ""  # also when the request is dropped while it waits: the child is killed
    try:
        ok = await _wait_readable(recv.fileno(), limits.seconds + 1)
        try:
            kind, value = recv.recv() if ok else ("time", "")
        except (EOFError, OSError):
            kind, value = "died", ""
    finally:
        if kind != "time":  # it answered, or its pipe closed: let it end by itself first
            await asyncio.get_running_loop().run_in_executor(None, p.join, 2)
        if p.is_alive():
            p.kill()
        await asyncio.get_running_loop().run_in_executor(None, p.join, 5)
        recv.close()
    if kind == "ok":
        return value
    raise HTTPException(*_refusal(kind, value, p.exitcode, limits, what))


def _refusal(kind: str, value: str, exitcode, limits: Limits, what: str) -> tuple[int, str]:
    if kind == "input":
        return 400, value
    if kind == "bug":
        return 400, f"{what} could not be read ({value}): check the file"
    if kind == "memory" or (kind == "died" and exitcode in (-signal.SIGSEGV, -signal.SIGABRT, -signal.SIGBUS)):
        return 413, (f"{what} needs more than {limits.memory_mb} MB to read (or broke the reader): "
                     "send a smaller or simpler file")
    if kind == "time" or exitcode == -signal.SIGXCPU:
        return 400, f"{what} took longer than {limits.seconds:g} s to read: send a smaller or simpler file"
    return 400, f"{what} could not be read (the reader stopped, exit code {exitcode}): check the file"


class Gate:
    """At most `slots` reads at once (the others wait, off the event loop's way), and at most
    `per_owner` of one token's reads in flight or waiting (more get 429): one token's uploads
    cannot take every slot."""

    def __init__(self, slots: int, per_owner: int):
        self.slots, self.per_owner = slots, per_owner
        self.sem: asyncio.Semaphore | None = None
        self.busy: dict[str, int] = {}

    async def run(self, owner: str, fn, *args, settings, limits: Limits, what: str):
        if self.busy.get(owner, 0) >= self.per_owner:
            raise HTTPException(429, f"{self.per_owner} of your uploads are being read: wait for them",
                                headers={"Retry-After": "5"})
        if self.sem is None:  # made on the event loop that uses it
            self.sem = asyncio.Semaphore(self.slots)
        self.busy[owner] = self.busy.get(owner, 0) + 1
        try:
            async with self.sem:
                return await fenced(fn, *args, settings=settings, limits=limits, what=what)
        finally:
            self.busy[owner] -= 1
            if not self.busy[owner]:
                del self.busy[owner]
