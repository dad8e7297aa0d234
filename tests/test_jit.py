"""engine.jit.serial_kernel: kernels compiled with numba's parallel pipeline must stay serial --
no array expression or np.zeros that numba would turn into a loop on its thread pool (those
stall when another process holds a core). Checked on the kernels as the solver really calls
them: a cloth falls onto a box for a few steps, then each serial kernel's parfor diagnostics are
read for the argument types it was called with -- numba keeps them for code compiled in this
process; code loaded from numba's cache has none, and is compiled afresh (uncached) to get them."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from numba import njit

from engine.cloth import kernels_carry as KR
from engine.cloth import kernels_contact as KC
from engine.cloth import kernels_forces as KF
from engine.cloth import kernels_integrate as KI
from engine.cloth import kernels_strain as KS
from engine.cloth import welds as W
from engine.cloth.buffers import limits2
from engine.cloth.config import Control, Sewing, StepConfig
from engine.cloth.fabrics import get_fabric
from engine.cloth.model import ClothState, build_model
from engine.cloth.solver import ClothSolver
from engine.collide import maps as M
from engine.collide import query as Q
from engine.collide.bvh import ObjectSpaceCollider
from engine.garment.garment import build_garment
from engine.pattern.spec import PatternSpec


def _serial_kernels():
    out = []
    for mod in (KR, KC, KF, KI, KS, W, Q, M):
        for name in dir(mod):
            f = getattr(mod, name)
            if hasattr(f, "py_func") and f.targetoptions.get("parallel") and "prange" not in _src(f):
                out.append((f"{mod.__name__}.{name}", f))
    return out


def _src(f):
    import inspect

    return inspect.getsource(f.py_func)


@pytest.mark.integration
def test_serial_kernels_compile_without_parallel_loops():
    spec = PatternSpec.model_validate({"pattern": {"panels": {"sq": {
        "vertices": [[0, 0], [20, 0], [20, 20], [0, 20]], "edges": [{"endpoints": [i, (i + 1) % 4]} for i in range(4)],
        "translation": [-10, 3, -10], "rotation": [90, 0, 0]}}, "stitches": []}})
    g = build_garment(spec, h=0.02)
    m = build_model(g.uv, g.panel, g.lattice, g.quads, g.tris, g.seams, get_fabric("cotton"), 0.02)
    box = trimesh.creation.box((0.3, 0.3, 0.3))
    solver = ClothSolver(m, ObjectSpaceCollider(np.asarray(box.vertices), np.asarray(box.faces), tolerance=0.005))
    state = ClothState(g.positions.copy(), np.zeros_like(g.positions))
    pairs = np.array([[0, 1]], np.int64)
    sewing = Control(sewing=Sewing(pairs, np.zeros(1, np.bool_), 0.02, 3.0))
    for _ in range(5):
        solver.step(state, sewing)
    W.hold_welds(state.x, state.v, m.mass, pairs, np.ones(1, np.bool_))
    W.seam_gaps(state.x, pairs, np.zeros(1))
    KI.kinetic_energy(state.v, m.mass), KS.max_strain(state.x, m.springs, m.rest, solver.model.strain_limited)
    KS.provot_positions(state.x, m.springs, m.rest, solver.model.strain_limited, 0.05, m.inv_mass, 2, solver.buf.work, False,
                       solver.buf.contact, solver.buf.contact_n)
    KS.inelastic_guard(state.x, solver.buf.x_guard, state.v)
    KI.hold_and_integrate(state.x, state.v, 1e-5, solver.buf.contact, solver.buf.contact_n, solver.buf.body_v)
    r = m.runs
    KS.guard_positions(state.x, state.v, m.springs, m.rest, solver.model.strain_limited, 0.05, m.inv_mass, 2, solver.buf.work,
                      solver.buf.contact, solver.buf.contact_n, 0.001, r.fast.perm, r.fast.runs, r.fast.springs, r.n_run,
                      limits2(solver.model, 0.05)[solver.buf.runs.fast.perm], solver.buf.soa, solver.buf.listed, solver.buf.listed_words, m.adj_ptr,
                      m.adj_spring, solver.buf.x_guard, solver.buf.saved, solver.buf.saved_list)
    solver = ClothSolver(m, solver.collider, StepConfig(late_guard=True))
    KS.guard_listed(state.x, state.v, m.springs, m.rest, solver.model.strain_limited, 0.05, m.inv_mass, 2, solver.buf.guard_work,
                   solver.buf.contact, solver.buf.contact_n, 0.001, solver.buf.listed, solver.buf.listed_words, m.adj_ptr,
                   m.adj_spring, solver.buf.x_guard, solver.buf.saved, solver.buf.saved_list, solver.buf.work, solver.buf.geo,
                   solver.buf.ends, 0, solver.buf.near, 0, limits2(solver.model, 0.05), 0.03)
    # the response on its own (the solver's contact_rounds does the same work; tests/test_cloth.py
    # compares them), on the last step's points
    npt = len(solver.buf.points)
    KC.collision_response(state.v, np.zeros(npt, np.int8), np.zeros((npt, 3)), np.zeros((npt, 3)), np.zeros(npt),
                         np.zeros((npt, 3)), m.n, m.quads, m.tris, 0.005, 0.0, 0.4, 1e-4, solver.buf.contact,
                         solver.buf.contact_n, solver.buf.body_v, 50.0)
    # the map query, on empty input with the map arrays' types
    Q.query_batch_serial(np.zeros((0, 3)), 0.005, np.zeros((2, 4, 4), np.float32), np.zeros((1, 1, 4), np.float32),
                         False, np.zeros((2, 4), np.int8), np.zeros((2, 4), np.int32), np.zeros((1, 3)),
                         np.zeros((1, 5), np.int32), np.zeros((2, 4, 2), np.float32), np.zeros(0, np.int8),
                         np.zeros((0, 3)), np.zeros(0),
                         np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int32))
    # the maps' pixel pass, on a 2 x 2 map pair
    M._finish_maps(np.zeros((2, 4, 4), np.float32), np.zeros((1, 1, 4), np.float32), False,
                   np.full((2, 4, 1), 0.5, np.float32), np.array([[2, 2, 0, 0, 2]], np.int32), 1,
                   np.zeros((2, 4), np.int8), np.zeros((2, 4), np.int32))
    kernels = _serial_kernels()
    assert len(kernels) >= 10, [n for n, _ in kernels]
    checked = []
    for name, f in kernels:
        if not f.signatures:
            continue
        fresh = None
        for sig in f.signatures:
            # compiled in this process (a fresh clone: no numba cache yet), numba kept the
            # diagnostics; loaded from the cache it did not: compile afresh, uncached
            diag = (f.overloads[sig].metadata or {}).get("parfor_diagnostics")
            if diag is None:
                if fresh is None:
                    fresh = njit(parallel=True, fastmath=f.targetoptions.get("fastmath", False),
                                 error_model=f.targetoptions.get("error_model", "python"))(f.py_func)
                fresh.compile(sig)
                diag = fresh.overloads[sig].metadata["parfor_diagnostics"]
            assert not diag.initial_parfors, f"{name} has a parallel loop (array expression / np.zeros?)"
        checked.append(name)
    for must in ("modify_velocities", "eval_forces_and_integrate", "collision_response", "query_batch_serial",
                 "pull_seams", "inelastic_guard", "guard_positions", "guard_listed", "hold_and_integrate",
                 "_finish_maps"):
        assert any(n.endswith("." + must) for n in checked), (must, checked)


def test_a_parallel_array_expression_is_caught():
    """The check above can fail: np.zeros in a parallel-compiled kernel shows up as a parfor."""

    def bad(a):
        b = np.zeros(a.shape[0])
        for i in range(a.shape[0]):
            b[i] = a[i]
        return b

    fresh = njit(parallel=True)(bad)
    fresh(np.ones(3))
    assert fresh.overloads[fresh.signatures[0]].metadata["parfor_diagnostics"].initial_parfors


@pytest.mark.parametrize("fn", ["modify_velocities", "collision_response"])
def test_serial_kernel_matches_plain_njit(fn):
    """Same results as plain @njit (the parallel pipeline only changes how fast it runs)."""
    rng = np.random.default_rng(1)
    n, s = 200, 800
    springs = rng.integers(0, n, (s, 2)).astype(np.int32)
    x = rng.normal(size=(n, 3))
    v = rng.normal(size=(n, 3))
    if fn == "modify_velocities":
        rest = np.linalg.norm(x[springs[:, 1]] - x[springs[:, 0]], axis=1) * 0.9
        args = (springs, rest, np.ones(s, np.bool_), 0.05, KS.VM_AVERAGE, np.array([0, -9.81, 0.0]), 1e-3,
                np.zeros((n, 3)), 6, np.zeros(s, np.int32), np.zeros((s, 4)), np.zeros((s, 2), np.int32), 0.002)
        outs = []
        for f in (KS.modify_velocities, njit(fastmath=True)(KS.modify_velocities.py_func)):
            vv = v.copy()
            outs.append((f(x, vv, *args), vv))
        assert outs[0][0] == outs[1][0] and np.allclose(outs[0][1], outs[1][1], atol=1e-12)
    else:
        quads = rng.integers(0, n, (50, 4)).astype(np.int32)
        tris = np.zeros((0, 3), np.int32)
        m = n + 50
        status = rng.integers(0, 3, m).astype(np.int8)
        nrm = rng.normal(size=(m, 3))
        nrm /= np.linalg.norm(nrm, axis=1)[:, None]
        pv = rng.normal(size=(m, 3))
        outs = []
        for f in (KC.collision_response, njit(fastmath=True)(KC.collision_response.py_func)):
            vv, c, cn, vb = v.copy(), np.zeros(n, np.bool_), np.zeros((n, 3)), np.zeros((n, 3))
            hits = f(vv, status, nrm, np.zeros((m, 3)), np.full(m, 0.003), pv, n,
                     quads, tris, 0.005, 0.0, 0.4, 1e-3, c, cn, vb, 50.0)
            outs.append((hits, vv, c))
        assert outs[0][0] == outs[1][0] and np.allclose(outs[0][1], outs[1][1]) and np.array_equal(outs[0][2], outs[1][2])
        assert outs[0][0] > 0


def test_the_kernel_cache_key_covers_the_kernel_files_it_imports(tmp_path):
    """A kernel inlines helpers from other files: its cache must go stale when a kernel file it
    imports changes, not only its own (engine.jit.KernelCacheLocator)."""
    import shutil

    from engine import jit

    root = tmp_path / "engine"
    shutil.copytree(jit.ENGINE, root, ignore=shutil.ignore_patterns("__pycache__"))
    names = {p.relative_to(root).as_posix() for p in jit.kernel_sources(root)}
    assert {"jit.py", "cloth/kernels_forces.py", "collide/server.py", "collide/moving.py", "collide/query.py"} <= names
    assert "cli.py" not in names  # (no kernels)
    moving, kernels = root / "collide" / "moving.py", root / "cloth" / "kernels_forces.py"
    stamp = jit.kernel_stamp.__wrapped__
    before = {f: stamp(f, root) for f in (moving, kernels)}
    helper = root / "collide" / "server.py"  # inlined into moving.py's kernels, not into kernels.py's
    helper.write_text(helper.read_text() + "\n# an edit to an inlined helper's file\n")
    assert stamp(moving, root) != before[moving]
    assert stamp(kernels, root) == before[kernels]
    jit_py = root / "jit.py"  # (both take their decorators from it)
    jit_py.write_text(jit_py.read_text() + "\n# an edit\n")
    assert stamp(kernels, root) != before[kernels]


def test_engine_kernels_are_cached_under_that_key():
    from pathlib import Path

    from engine import jit

    assert KI.integrate_positions._cache._impl.locator.__class__ is jit.KernelCacheLocator
    assert KI.integrate_positions._cache._impl.locator.get_source_stamp() == jit.kernel_stamp(Path(KI.__file__))
    for p in jit.ENGINE.rglob("*.py"):  # every kernel file takes numba's decorators from engine.jit
        if p.name != "jit.py":
            assert "from numba import" not in p.read_text(), p
