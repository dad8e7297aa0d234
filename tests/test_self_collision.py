"""Cloth-cloth contact within one cloth (engine.cloth.selfcontact): layers dropped on each other
stay apart, a fold does not pass through itself, a flat sheet is left bit for bit alone, the pass is
deterministic and bounded, absurd settings are refused. Crossings are counted here by brute force
(every triangle pair, NumPy), independently of the pass and of its own counter."""

from __future__ import annotations

import numpy as np
import pytest

from engine.cloth.config import Control, StepConfig
from engine.cloth.fabrics import get_fabric
from engine.cloth.model import ClothState, build_model
from engine.cloth.selfcontact import SelfContact, all_triangles, self_intersections
from engine.cloth.solver import ClothSolver
from engine.errors import InputError
from engine.garment.garment import build_garment
from engine.pattern.spec import PatternSpec
from tests.test_cloth import _CountingCollider as Floor  # a flat floor at y = 0 with a 5 mm band


@pytest.fixture(scope="module", autouse=True)
def one_numba_thread():
    """Tiny meshes: parallel kernels would wait for busy cores far longer than they compute."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


def _spec(panels: dict) -> PatternSpec:
    """Rectangles {name: (width cm, depth cm, x offset cm)}, no stitches."""
    return PatternSpec.model_validate({"pattern": {"panels": {
        k: {"vertices": [[0, 0], [w, 0], [w, d], [0, d]], "edges": [{"endpoints": [i, (i + 1) % 4]} for i in range(4)],
            "translation": [x0, 0, 0]} for k, (w, d, x0) in panels.items()}, "stitches": []}})


def _model(garment, h):
    g = garment
    return build_model(g.uv, g.panel, g.lattice, g.quads, g.tris, g.seams, get_fabric("cotton"), h)


def _run(model, x, on: bool, steps: int, **cfg):
    solver = ClothSolver(model, Floor(), StepConfig(self_collision=on, **cfg))
    state = ClothState(x.copy(), np.zeros_like(x))
    control = Control(collide_every=2)
    for _ in range(steps):
        solver.step(state, control)
    return state, solver


def crossings(x: np.ndarray, tris: np.ndarray) -> int:
    """Triangle pairs sharing no corner of which an edge of one passes through the other: brute
    force (Moller-Trumbore for the 6 edges) over every pair whose centroids are near enough to
    touch (closer than two of the longest triangle edge)."""
    from scipy.spatial import cKDTree

    corners = x[tris]
    longest = float(np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max())
    near = np.array(sorted(cKDTree(corners.mean(axis=1)).query_pairs(2.0 * longest)), dtype=np.int64).reshape(-1, 2)
    i, j = near[:, 0], near[:, 1]
    share = (tris[i][:, :, None] == tris[j][:, None, :]).any(axis=(1, 2))
    i, j = i[~share], j[~share]
    hit = np.zeros(len(i), dtype=bool)
    for s, t in ((i, j), (j, i)):
        a, b, c = (x[tris[t][:, k]] for k in range(3))
        for e0, e1 in ((0, 1), (1, 2), (2, 0)):
            p, q = x[tris[s][:, e0]], x[tris[s][:, e1]]
            d, e1v, e2v = q - p, b - a, c - a
            hv = np.cross(d, e2v)
            det = np.einsum("ij,ij->i", e1v, hv)
            ok = np.abs(det) > 1e-20
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            sv = p - a
            u = inv * np.einsum("ij,ij->i", sv, hv)
            r = np.cross(sv, e1v)
            w = inv * np.einsum("ij,ij->i", d, r)
            tt = inv * np.einsum("ij,ij->i", e2v, r)
            hit |= ok & (u >= 0) & (w >= 0) & (u + w <= 1) & (tt >= 0) & (tt <= 1)
    return int(hit.sum())


@pytest.fixture(scope="module")
def two_sheets():
    """Sheet a (20 x 20 cm) lying 1 cm above the floor; sheet b, offset 5 cm in x, above it and
    tilted (one side 3 cm lower) -- it falls on a and, beside it, on the floor."""
    h = 0.02
    g = build_garment(_spec({"a": (20, 20, 0), "b": (20, 20, 5)}), h=h)
    p = g.positions
    x = np.stack([p[:, 0], np.zeros(len(p)), p[:, 1]], axis=1)
    b = g.panel == 1
    x[~b, 1] = 0.01
    x[b, 1] = 0.04 + 0.3 * (x[b, 0] - x[b, 0].mean())
    return _model(g, h), x, b


def test_two_sheets_dropped_on_each_other_stay_apart(two_sheets):
    model, x, b = two_sheets
    tris = all_triangles(model.quads, model.tris)
    off, _ = _run(model, x, False, 3000)
    on, solver = _run(model, x, True, 3000)
    # without the pass the falling sheet passes through the lower one (the test can fail) ...
    assert crossings(off.x, tris) > 50
    assert np.isfinite(on.x).all() and np.isfinite(on.v).all()
    # ... with it, nothing crosses, and where b lies over a it lies on top, about a layer apart
    assert crossings(on.x, tris) == 0
    assert self_intersections(on.x, tris)["pairs"] == 0  # (the pass's own counter agrees)
    over = b & (x[:, 0] < 0.2 - 0.02)
    a_top = on.x[~b, 1].max()
    assert on.x[over, 1].min() > a_top - 0.001
    assert solver.self_contact.found > 0


def test_a_sheet_folded_over_itself_does_not_pass_through():
    """A 40 x 16 cm sheet folded in two (a 1 cm round crease), the top half 2 cm above the
    bottom one, dropped on the floor: the top half settles on the bottom one, not into it."""
    h = 0.01
    g = build_garment(_spec({"s": (40, 16, 0)}), h=h)
    u, v = g.positions[:, 0], g.positions[:, 1]
    r, half = 0.01, 0.2 - np.pi * 0.01 / 2
    a = np.clip((u - half) / r, 0.0, np.pi)  # the angle round the crease
    x = np.stack([np.where(u <= half, u, np.where(a < np.pi, half + r * np.sin(a), half - (u - half - np.pi * r))),
                  0.01 + np.where(u <= half, 0.0, r * (1 - np.cos(a))), v], axis=1)
    model = _model(g, h)
    tris = all_triangles(model.quads, model.tris)
    assert crossings(x, tris) == 0
    off, _ = _run(model, x, False, 2500)
    on, _ = _run(model, x, True, 2500)
    assert crossings(off.x, tris) > 20
    assert crossings(on.x, tris) == 0
    top = u > 0.2 + 0.02
    assert on.x[top, 1].min() > on.x[u < 0.2 - 0.04, 1].max()


def test_a_flat_sheet_is_left_bit_for_bit_alone():
    """Vertices near each other on the pattern are never pushed apart: a fine sheet falling on the
    floor and lying there steps the same, bit for bit, with the pass on (even with a layer 2.5
    edges thick) as off."""
    h = 0.005
    g = build_garment(_spec({"s": (12, 12, 0)}), h=h)
    p = g.positions
    x = np.stack([p[:, 0], np.full(len(p), 0.02), p[:, 1]], axis=1)
    model = _model(g, h)
    off, _ = _run(model, x, False, 800)
    for thickness in (0.003, 2.5 * h):
        on, solver = _run(model, x, True, 800, self_thickness=thickness, self_every=1)
        assert np.array_equal(on.x, off.x) and np.array_equal(on.v, off.v)
        assert solver.self_contact.found == 0


def test_the_pass_is_deterministic(two_sheets):
    model, x, _ = two_sheets
    s1, _ = _run(model, x, True, 600)
    s2, _ = _run(model, x, True, 600)
    assert np.array_equal(s1.x, s2.x) and np.array_equal(s1.v, s2.v)


def test_a_crumpled_heap_keeps_its_memory_bounded(two_sheets):
    """Every vertex within a layer of every triangle (a heap 2 mm across): the pairs listed stop
    at the cap, the rest are counted as dropped, nothing turns NaN."""
    model, x, _ = two_sheets
    rng = np.random.default_rng(3)
    heap = ClothState(0.1 + 0.002 * rng.random((model.n, 3)), rng.normal(0.0, 0.5, (model.n, 3)))
    sc = SelfContact(model, 0.003, 1)
    sc.step(heap, 0, 1e-4, 50.0, 0.3)
    assert sc.dropped > 0 and sc.n_cand == len(sc.cand_v) <= sc.cap
    assert 0 < sc.found <= sc.n_cand
    assert np.isfinite(heap.v).all()


@pytest.mark.parametrize("field,bad", [("self_thickness", 0.0), ("self_thickness", -0.001),
                                       ("self_thickness", float("nan")), ("self_thickness", 0.5),
                                       ("self_every", 0), ("self_every", 1000), ("self_every", 2.5)])
def test_absurd_settings_are_refused(field, bad):
    with pytest.raises(InputError, match=field):
        StepConfig(self_collision=True, **{field: bad})


def test_a_layer_thick_against_the_cloth_edges_is_refused():
    h = 0.005  # at most 15 mm
    model = _model(build_garment(_spec({"s": (10, 10, 0)}), h=h), h)
    ClothSolver(model, None, StepConfig(self_collision=True, self_thickness=0.015))
    with pytest.raises(InputError, match="at most 3 cloth edges"):
        ClothSolver(model, None, StepConfig(self_collision=True, self_thickness=0.016))


def test_the_crossing_counter_agrees_with_brute_force(two_sheets):
    model, x, _ = two_sheets
    tris = all_triangles(model.quads, model.tris)
    off, _ = _run(model, x, False, 3000)
    assert self_intersections(off.x, tris)["pairs"] == crossings(off.x, tris) > 0


def _placed(panels: dict, stitches: list | None = None):
    """Rectangles {name: (width cm, height cm, translation (x, y, z) cm)}, in the xy plane."""
    return build_garment(PatternSpec.model_validate({"pattern": {"panels": {
        k: {"vertices": [[0, 0], [w, 0], [w, d], [0, d]], "edges": [{"endpoints": [i, (i + 1) % 4]} for i in range(4)],
            "translation": list(t)} for k, (w, d, t) in panels.items()}, "stitches": stitches or []}}), h=0.015)


def test_the_scene_turns_it_on_for_panels_placed_on_each_other():
    """DrapeTuning.self_contact "auto": on where a panel is placed on another (a cuff over its
    sleeve), off for panels apart or meeting only at their seam; "on"/"off" force it."""
    from dataclasses import replace

    from engine.scene.drape import dressing_config
    from engine.scene.layers import needs_self_contact
    from engine.scene.request import TryOnOptions
    from engine.scene.tuning import Tuning

    t = Tuning()
    layered = _placed({"sleeve": (30, 40, (0, 0, 0)), "cuff": (30, 8, (0, 2, 1.5))})
    apart = _placed({"a": (30, 40, (0, 0, 0)), "b": (30, 40, (0, 0, 30))})
    seam = [[{"panel": "a", "edge": 1}, {"panel": "b", "edge": 3}]]
    sewn = _placed({"a": (30, 40, (0, 0, 0)), "b": (30, 40, (30.5, 0, 0))}, seam)
    assert needs_self_contact(layered, t)[0]
    assert not needs_self_contact(apart, t)[0]
    assert not needs_self_contact(sewn, t)[0]
    assert needs_self_contact(_placed({"a": (30, 40, (0, 0, 0)), "b": (30, 40, (30.5, 0, 0))}), t)[0]  # (no seam)
    assert needs_self_contact(apart, replace(t, drape=replace(t.drape, self_contact="on")))[0]
    assert not needs_self_contact(layered, replace(t, drape=replace(t.drape, self_contact="off")))[0]
    assert dressing_config(TryOnOptions(), t, True).self_collision
    assert not dressing_config(TryOnOptions(), t, False).self_collision
    assert not dressing_config(TryOnOptions(), replace(t, drape=replace(t.drape, self_contact="off")), True).self_collision
    for bad in ({"self_contact": "yes"}, {"layer_gap": 0.0}, {"layer_share": 2.0}, {"layer_clear": float("nan")}):
        with pytest.raises(InputError):
            replace(t, drape=replace(t.drape, **bad)).validate()
