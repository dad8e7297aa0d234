"""A peer side by side: our explicit cloth step against Newton's semi-implicit cloth solver
(NVIDIA Warp kernels, on the CPU) for the same hanging cloth -- a square sheet of N x N vertices,
1.5 cm apart, cotton's mass, pinned along one edge, no body -- at the same time step (our eq. 4
bound). Per-step time from one run after a warm-up; Newton's first step (kernel compilation, or
loading from Warp's cache) reported separately. Newton's cloth is triangle FEM with bending (its
own model and defaults), ours is the mass-spring model with velocity modification: the same
size of problem, not the same mathematics.

Needs `newton` and `warp-lang` (not in the default install: `make bench-peer`).
"""

from __future__ import annotations

import time

import numpy as np


def _our_sheet(n: int, h: float):
    from engine.cloth.fabrics import get_fabric
    from engine.cloth.model import ClothState, build_model

    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    lattice = np.stack([i.ravel(), j.ravel()], axis=1).astype(np.int64)
    uv = lattice * h
    idx = (i * n + j)
    quads = np.stack([idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()], axis=1)
    model = build_model(uv.astype(float), np.zeros(n * n, np.int64), lattice, quads.astype(np.int64),
                        np.zeros((0, 3), np.int64), np.zeros((0, 2), np.int64), get_fabric("cotton"), h)
    x = np.zeros((n * n, 3))
    x[:, 0] = uv[:, 0]
    x[:, 1] = 1.5 - uv[:, 1]  # hanging in the x-y plane, top row (j = 0) pinned
    pinned = np.flatnonzero(lattice[:, 1] == 0)
    return model, ClothState(x, np.zeros_like(x)), pinned


def compare(quick: bool, say) -> dict:
    import tempfile

    import warp as wp

    wp.config.quiet = True
    # a fresh kernel cache, so that the first step measures Warp's compilation (a later run of
    # the same user would load the cached kernels in well under a second)
    cache = tempfile.mkdtemp(prefix="tryon-warp-cache-")
    wp.config.kernel_cache_dir = cache
    import newton

    from engine.cloth.solver import ClothSolver

    sizes = (32,) if quick else (32, 64)
    steps = 100 if quick else 300
    h = 0.015
    rows = []
    for n in sizes:
        model, state, pinned = _our_sheet(n, h)
        x0 = state.x[pinned].copy()
        solver = ClothSolver(model, None)
        dt = solver.dt
        for _ in range(10):
            solver.step(state)
        t0 = time.perf_counter()
        for _ in range(steps):
            solver.step(state)
            state.x[pinned] = x0
            state.v[pinned] = 0.0
        ours = 1000 * (time.perf_counter() - t0) / steps
        rows.append({"solver": "ours (explicit mass-spring + velocity modification, numba)", "vertices": n * n,
                     "ms_per_step": ours, "dt_ms": dt * 1000})
        say(f"peer ours {n * n} v: {ours:.3f} ms/step")

        for tri_contact in ((False, True) if n <= 32 else (False,)):  # its self-contact is O(N T)
            builder = newton.ModelBuilder()
            mass = float(model.mass.mean())
            builder.add_cloth_grid(pos=wp.vec3(0.0, 1.5, 0.0), rot=wp.quat_identity(), vel=wp.vec3(0.0, 0.0, 0.0),
                                   dim_x=n - 1, dim_y=n - 1, cell_x=h, cell_y=h, mass=mass, fix_left=True)
            nm = builder.finalize(device="cpu")
            ns = newton.solvers.SolverSemiImplicit(model=nm, enable_tri_contact=tri_contact)
            s0, s1, ctrl = nm.state(), nm.state(), nm.control()
            t0 = time.perf_counter()
            s0.clear_forces()
            ns.step(s0, s1, ctrl, None, dt)
            s0, s1 = s1, s0
            first = time.perf_counter() - t0
            for _ in range(10):
                s0.clear_forces()
                ns.step(s0, s1, ctrl, None, dt)
                s0, s1 = s1, s0
            wp.synchronize()
            m = steps if not tri_contact else max(5, steps // 20)  # self-contact is O(N T): fewer steps
            t0 = time.perf_counter()
            for _ in range(m):
                s0.clear_forces()
                ns.step(s0, s1, ctrl, None, dt)
                s0, s1 = s1, s0
            wp.synchronize()
            theirs = 1000 * (time.perf_counter() - t0) / m
            q = s0.particle_q.numpy()
            what = "with its cloth self-contact (default)" if tri_contact else "self-contact off (as ours)"
            rows.append({"solver": f"Newton {newton.__version__} SolverSemiImplicit, {what} (Warp {wp.config.version}, CPU)",
                         "vertices": int(nm.particle_count), "ms_per_step": theirs, "compile_s": first,
                         "dt_ms": dt * 1000, "finite": bool(np.all(np.isfinite(q)))})
            say(f"peer newton ({what}) {nm.particle_count} v: {theirs:.3f} ms/step (first step {first:.1f} s)")
    import shutil

    shutil.rmtree(cache, ignore_errors=True)
    return {"available": True, "rows": rows, "note": (
        f"A hanging cotton sheet, 1.5 cm grid, pinned along one edge, no body; {steps} steps at our eq. 4 "
        "time step after a warm-up, on this machine. Newton's first-step time is its kernels' compilation "
        "into an empty Warp kernel cache (the first size pays it; later ones reuse the kernels).")}
