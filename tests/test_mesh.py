"""Meshing panels (grid clipped to the outline + a triangulated band) and building a garment."""

from __future__ import annotations

import math

import numpy as np
import pytest
from matplotlib.path import Path as MplPath
from scipy.spatial import cKDTree

from engine.errors import InputError
from engine.garment.garment import build_garment, spec_placement
from engine.garment.mesh import mesh_panel
from engine.pattern import geometry as geo
from engine.pattern.io import load_pattern
from tests.samples import SAMPLE_SKIRT

H = 0.02


@pytest.fixture(scope="module")
def skirt():
    return load_pattern(SAMPLE_SKIRT)


def _polygon_edges(corners: np.ndarray, h: float) -> list[np.ndarray]:
    """Straight edges between consecutive corners, each sampled at about h."""
    out = []
    for i in range(len(corners)):
        a, b = corners[i], corners[(i + 1) % len(corners)]
        n = max(1, math.ceil(np.linalg.norm(b - a) / h))
        t = np.linspace(0, 1, n + 1)[:, None]
        out.append(a + t * (b - a))
    return out


def _reverse(edge_points: list[np.ndarray]) -> list[np.ndarray]:
    return [e[::-1] for e in edge_points[::-1]]


SQUARE = np.array([[0, 0], [0.2, 0], [0.2, 0.2], [0, 0.2]], dtype=float)
L_SHAPE = np.array([[0, 0], [0.3, 0], [0.3, 0.12], [0.12, 0.12], [0.12, 0.3], [0, 0.3]], dtype=float)


def _sample_panel_edges(skirt, name, h):
    p = skirt.pattern.panels[name]
    return [geo.edge_samples(p, e, skirt.scale, max(1, math.ceil(geo.edge_length(p, e, skirt.scale) / h)))
            for e in p.edges]


def _h(name: str) -> float:
    return 0.008 if name.startswith("wb_") else H  # waistbands are 3.5 cm tall: a finer grid fits


def _cases(skirt):
    cases = {"square": _polygon_edges(SQUARE, H), "L": _polygon_edges(L_SHAPE, H)}
    for name in skirt.pattern.panels:
        cases[name] = _sample_panel_edges(skirt, name, _h(name))
    return cases


def _shoelace(poly):
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _face_signed_areas(uv, faces):
    return np.array([_shoelace(uv[f]) for f in faces]) if len(faces) else np.zeros(0)


CASE_NAMES = ["square", "L", "skirt_front", "skirt_back", "wb_back", "wb_front"]


@pytest.fixture(scope="module")
def meshes(skirt):
    """name -> (edge_points, ring, mesh of the outline as given, mesh of the reversed outline)."""
    out = {}
    for name, edges in _cases(skirt).items():
        ring = np.concatenate([e[:-1] for e in edges])
        out[name] = (edges, ring, mesh_panel(edges, _h(name), name), mesh_panel(_reverse(edges), _h(name), name))
    return out


@pytest.mark.parametrize("name", CASE_NAMES)
def test_outline_samples_are_vertices(meshes, name):
    edges, ring, m, _ = meshes[name]
    assert len(m.edge_vertices) == len(edges)
    for pts, ev in zip(edges, m.edge_vertices):
        assert len(ev) == len(pts)
        np.testing.assert_allclose(m.uv[ev], pts, atol=1e-12)
    # consecutive edges share their corner vertex
    for i in range(len(edges)):
        assert m.edge_vertices[i][-1] == m.edge_vertices[(i + 1) % len(edges)][0]


@pytest.mark.parametrize("name", CASE_NAMES)
def test_faces_inside_and_area(meshes, name):
    _, ring, m, _ = meshes[name]
    path = MplPath(ring)
    faces = [f for f in (m.quads, m.tris) if len(f)]
    cen = np.concatenate([m.uv[f].mean(axis=1) for f in faces])
    assert path.contains_points(cen).all()
    # every vertex inside or on the outline
    inside = path.contains_points(m.uv, radius=1e-9) | path.contains_points(m.uv, radius=-1e-9)
    assert inside.all()
    area = np.abs(_face_signed_areas(m.uv, m.quads)).sum() + np.abs(_face_signed_areas(m.uv, m.tris)).sum()
    assert area == pytest.approx(abs(_shoelace(ring)), rel=0.01)


@pytest.mark.parametrize("name", CASE_NAMES)
def test_mesh_is_a_disc_bounded_by_the_outline(meshes, name):
    """Each interior edge is shared by exactly two faces with opposite directions, and the
    edges used once are exactly the outline segments (no holes, no overlaps, no gaps)."""
    _, ring, m, _ = meshes[name]
    nb = len(ring)
    directed = []
    for f in [m.quads, m.tris]:
        for k in range(f.shape[1]):
            directed.append(np.stack([f[:, k], f[:, (k + 1) % f.shape[1]]], axis=1))
    d = np.concatenate(directed)
    dset = {tuple(e) for e in d.tolist()}
    assert len(dset) == len(d), "a directed edge used twice: inconsistent winding or overlap"
    und, cnt = np.unique(np.sort(d, axis=1), axis=0, return_counts=True)
    assert cnt.max() <= 2
    boundary = {tuple(e) for e in und[cnt == 1].tolist()}
    outline = {tuple(sorted((i, (i + 1) % nb))) for i in range(nb)}
    assert boundary == outline


@pytest.mark.parametrize("name", CASE_NAMES)
def test_quads_are_grid_cells_of_side_h(meshes, name):
    _, _, m, _ = meshes[name]
    h = _h(name)
    assert len(m.quads) > 0
    q = m.uv[m.quads]
    sides = np.linalg.norm(q - np.roll(q, -1, axis=1), axis=2)
    np.testing.assert_allclose(sides, h, rtol=1e-9)
    diag = np.linalg.norm(q[:, 2] - q[:, 0], axis=1)
    np.testing.assert_allclose(diag, h * np.sqrt(2), rtol=1e-9)
    # interior vertices are on the lattice, outline vertices are marked -1
    nb = sum(len(e) - 1 for e in meshes[name][0])
    assert np.all(m.lattice[:nb] == -1) and np.all(m.lattice[nb:] >= 0)


@pytest.mark.parametrize("name", CASE_NAMES)
def test_winding_follows_outline(meshes, name):
    _, ring, m, m_rev = meshes[name]
    ccw, cw = (m, m_rev) if _shoelace(ring) > 0 else (m_rev, m)
    assert ccw.ccw and not cw.ccw
    assert len(ccw.quads) == len(cw.quads) and len(ccw.tris) + len(cw.tris) > 0
    for f in (ccw.quads, ccw.tris):
        assert np.all(_face_signed_areas(ccw.uv, f) > 0)
    for f in (cw.quads, cw.tris):
        assert np.all(_face_signed_areas(cw.uv, f) < 0)


@pytest.mark.parametrize("name", CASE_NAMES)
def test_no_duplicate_or_crowded_vertices(meshes, name):
    _, _, m, _ = meshes[name]
    tree = cKDTree(m.uv)
    assert not tree.query_pairs(1e-6)
    d, _ = tree.query(m.uv, k=2)
    assert d[:, 1].min() > 0.2 * _h(name)  # lattice points within h/2 of the outline were dropped
    used = np.zeros(len(m.uv), bool)
    used[np.concatenate([m.quads.ravel(), m.tris.ravel()])] = True
    assert used.all(), "every vertex belongs to a face"


def test_l_shape_keeps_its_notch(meshes):
    _, _, m, _ = meshes["L"]
    notch = (m.uv[:, 0] > 0.12 + 1e-9) & (m.uv[:, 1] > 0.12 + 1e-9)
    assert not notch.any()


def test_mesh_refusals():
    with pytest.raises(InputError, match="positive"):
        mesh_panel(_polygon_edges(SQUARE, H), 0.0, "sq")
    with pytest.raises(InputError, match="too small"):
        mesh_panel(_polygon_edges(SQUARE * 0.05, H), H, "tiny")


# --- garment ----------------------------------------------------------------------------------------

GH = 0.03


@pytest.fixture(scope="module")
def garment(skirt):
    return build_garment(skirt, h=GH)


def test_garment_arrays(garment, skirt):
    n = garment.n_vertices
    assert garment.positions.shape == (n, 3) and garment.uv.shape == (n, 2)
    assert garment.panel_names == skirt.pattern.panel_order == ["wb_back", "skirt_back", "skirt_front", "wb_front"]
    assert set(np.unique(garment.panel)) == set(range(4))
    t = garment.triangles()
    assert t.shape == (len(garment.tris) + 2 * len(garment.quads), 3)
    assert t.dtype == np.int32 and t.min() >= 0 and t.max() < n
    assert np.all(np.isfinite(garment.positions))


def test_stitches_pair_vertex_for_vertex(garment, skirt):
    scale = skirt.scale
    panels = skirt.pattern.panels
    total = 0
    for s, (a, b) in enumerate(skirt.pattern.stitches):
        pairs = garment.seams[garment.seam_id == s]
        la = geo.edge_length(panels[a.panel], panels[a.panel].edges[a.edge], scale)
        lb = geo.edge_length(panels[b.panel], panels[b.panel].edges[b.edge], scale)
        expected = max(math.ceil(la / GH), math.ceil(lb / GH)) + 1
        assert len(pairs) == expected
        total += expected
        for col, side in ((0, a), (1, b)):
            v = pairs[:, col]
            assert len(np.unique(v)) == len(v)
            assert np.all(garment.panel[v] == garment.panel_names.index(side.panel))
            # on that edge's curve, evenly spaced
            p = panels[side.panel]
            curve = geo.resample(geo.edge_dense(p, p.edges[side.edge], scale), 2000)
            d = np.min(np.linalg.norm(garment.uv[v][:, None] - curve[None], axis=2), axis=1)
            assert d.max() < 2e-3
            step = np.linalg.norm(np.diff(garment.uv[v], axis=0), axis=1)
            assert step.max() / step.min() < 1.05
    assert len(garment.seams) == total
    assert garment.seams.shape == (total, 2) and garment.seam_id.shape == (total,)


def test_stitches_sew_head_to_tail(garment, skirt):
    """With the spec's own placement, the first pair of each stitch starts at the same end:
    closer than the flipped pairing (GarmentCode sews the edges head to tail)."""
    x = build_garment(skirt, h=GH, place=spec_placement(skirt)).positions
    for s in range(len(skirt.pattern.stitches)):
        pairs = garment.seams[garment.seam_id == s]
        first = np.linalg.norm(x[pairs[0, 0]] - x[pairs[0, 1]])
        flipped = np.linalg.norm(x[pairs[0, 0]] - x[pairs[-1, 1]])
        assert first < flipped, garment.stitch_names[s]
        same = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1).mean()
        flip = np.linalg.norm(x[pairs[:, 0]] - x[pairs[::-1, 1]], axis=1).mean()
        assert same < flip, garment.stitch_names[s]


def test_side_seam_pairs_the_waist_corners(garment, skirt):
    """skirt_front edge 0 runs v0 -> v1 (waist -> hem), skirt_back edge 3 runs v3 -> v0 (hem ->
    waist): the pairing must join front v0 with back v0 (both at the waist)."""
    s = 0
    a, b = skirt.pattern.stitches[s]
    assert (a.panel, a.edge, b.panel, b.edge) == ("skirt_front", 0, "skirt_back", 3)
    pairs = garment.seams[garment.seam_id == s]
    fv0 = np.asarray(skirt.pattern.panels["skirt_front"].vertices[0]) * skirt.scale
    bv0 = np.asarray(skirt.pattern.panels["skirt_back"].vertices[0]) * skirt.scale
    np.testing.assert_allclose(garment.uv[pairs[0, 0]], fv0, atol=1e-12)
    np.testing.assert_allclose(garment.uv[pairs[0, 1]], bv0, atol=1e-12)


def test_spec_placement_puts_panels_where_the_spec_says(garment, skirt):
    """Rotation 0: a panel point (u, v) goes to translation + (u, v, 0), in metres."""
    for k, name in enumerate(garment.panel_names):
        sel = garment.panel == k
        t = np.asarray(skirt.pattern.panels[name].translation) * skirt.scale
        expect = np.column_stack([garment.uv[sel], np.zeros(sel.sum())]) + t
        np.testing.assert_allclose(garment.positions[sel], expect, atol=1e-12)


def test_build_garment_refusals(skirt):
    with pytest.raises(InputError, match="out of range"):
        build_garment(skirt, h=0.0)
    with pytest.raises(InputError, match="out of range"):
        build_garment(skirt, h=1.0)


def test_farther_than_matches_every_distance():
    """mesh.farther_than (the lattice points kept away from the outline) against all the
    point-segment distances in numpy, on a wavy closed outline and points spread across and
    around it, at two radii."""
    from engine.garment.mesh import farther_than

    rng = np.random.default_rng(7)
    th = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    poly = np.stack([(0.3 + 0.05 * np.sin(5 * th)) * np.cos(th), (0.2 + 0.03 * np.cos(7 * th)) * np.sin(th)], 1)
    p = rng.uniform(-0.4, 0.4, (4000, 2))
    a, b = poly, np.roll(poly, -1, axis=0)
    ab, ap = b - a, p[:, None, :] - a[None]
    t = np.clip((ap * ab[None]).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-30)[None], 0.0, 1.0)
    dist = np.linalg.norm(ap - t[..., None] * ab[None], axis=-1).min(axis=1)
    for r in (0.0075, 0.03):
        got = farther_than(p, poly, r, np.empty(len(p), dtype=np.bool_))
        want = dist > r
        assert 0.05 < want.mean() < 0.95
        assert np.array_equal(got, want)
