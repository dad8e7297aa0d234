"""engine.collide.bvh against independent references: trimesh's closest-point routine run over ALL
triangles (brute force), the generalised winding number (exact inside/outside for a closed mesh,
computed brute force), and analytic shapes (sphere, box, linear velocity fields).

trimesh's `mesh.contains` needs rtree, which is not in the lock; where it is importable it is
checked as well, otherwise the winding number (which has no ray/edge degeneracies) stands in."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from numba import njit, prange

from tests.samples import SAMPLE_BODY
from engine.collide.bvh import (BAND, CLEAR, INSIDE, MeshBVH, ObjectSpaceCollider,
                                penetration_stats)

BODY = SAMPLE_BODY


def _body_path():
    assert BODY.exists(), f"sample body missing: {BODY} (../shared/samples beside the repository)"
    return BODY


@pytest.fixture(scope="module")
def body():
    m = trimesh.load(_body_path(), process=False)
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int32)


def _sphere(r=0.3, sub=3):
    m = trimesh.creation.icosphere(subdivisions=sub, radius=r)
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int32)


def _box(ext=(0.4, 0.2, 0.1)):
    m = trimesh.creation.box(extents=ext)
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int32)


MESHES = {"icosphere": _sphere, "box": _box}


def _mesh(name, body):
    return body if name == "body" else MESHES[name]()


def _sample_points(v, f, n, rng, near=0.05):
    """Half near the surface (surface samples pushed up to `near` along +-normal, like cloth),
    half uniform in the box grown by 10 %."""
    m = trimesh.Trimesh(v, f, process=False)
    s, fi = trimesh.sample.sample_surface(m, n // 2, seed=int(rng.integers(1 << 31)))
    s = s + m.face_normals[fi] * rng.uniform(-near, near, (len(s), 1))
    lo, hi = v.min(0), v.max(0)
    pad = 0.1 * (hi - lo)
    u = rng.uniform(lo - pad, hi + pad, (n - len(s), 3))
    return np.concatenate([s, u])


@njit(cache=True, parallel=True)
def _winding(points, tri):
    """Generalised winding number (Van Oosterom & Strackee solid angles), brute force."""
    out = np.empty(points.shape[0])
    for p in prange(points.shape[0]):
        px, py, pz = points[p, 0], points[p, 1], points[p, 2]
        acc = 0.0
        for t in range(tri.shape[0]):     # scalars only: no temporaries in the inner loop
            ax, ay, az = tri[t, 0, 0] - px, tri[t, 0, 1] - py, tri[t, 0, 2] - pz
            bx, by, bz = tri[t, 1, 0] - px, tri[t, 1, 1] - py, tri[t, 1, 2] - pz
            cx, cy, cz = tri[t, 2, 0] - px, tri[t, 2, 1] - py, tri[t, 2, 2] - pz
            la = math.sqrt(ax * ax + ay * ay + az * az)
            lb = math.sqrt(bx * bx + by * by + bz * bz)
            lc = math.sqrt(cx * cx + cy * cy + cz * cz)
            det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
            den = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc
                   + (bx * cx + by * cy + bz * cz) * la + (cx * ax + cy * ay + cz * az) * lb)
            acc += 2.0 * math.atan2(det, den)
        out[p] = acc / (4.0 * math.pi)
    return out


# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["icosphere", "box", "body"])
def test_closest_matches_brute_force(name, body):
    v, f = _mesh(name, body)
    rng = np.random.default_rng(1)
    pts = _sample_points(v, f, 200 if name == "body" else 400, rng)
    bvh = MeshBVH(v, f)
    dist, cp, normal, face, bary = bvh.closest(pts)
    tri = v[f]
    ref = np.empty(len(pts))
    for i, q in enumerate(pts):       # brute force: every triangle, trimesh's own routine
        c = trimesh.triangles.closest_point(tri, np.broadcast_to(q, tri.shape[:1] + (3,)))
        ref[i] = np.sqrt(((c - q) ** 2).sum(1)).min()
    np.testing.assert_allclose(dist, ref, rtol=0, atol=1e-9)
    # the reported point is on the reported triangle at the reported barycentrics
    assert np.all(face >= 0)
    np.testing.assert_allclose(bary.sum(1), 1.0, atol=1e-12)
    assert np.all(bary >= -1e-12)
    np.testing.assert_allclose(np.einsum("ni,nij->nj", bary, tri[face]), cp, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(pts - cp, axis=1), dist, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(normal, axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("name", ["icosphere", "box", "body"])
def test_sign_matches_winding_number(name, body):
    v, f = _mesh(name, body)
    rng = np.random.default_rng(2)
    pts = _sample_points(v, f, 3000, rng, near=0.03)
    sd = MeshBVH(v, f).signed_distance(pts)
    keep = np.abs(sd) > 1e-3            # on-surface points have no reliable reference sign
    assert keep.sum() > 2000
    w = _winding(pts[keep], v[f])
    # closed mesh: winding is 0 or 1 away from the surface
    assert np.all(np.minimum(np.abs(w), np.abs(w - 1.0)) < 1e-6)
    np.testing.assert_array_equal(sd[keep] < 0, w > 0.5)
    assert 200 < (sd[keep] < 0).sum() < keep.sum() - 200     # both sides exercised


def test_sign_matches_trimesh_contains(body):
    pytest.importorskip("rtree")          # trimesh's ray test needs it
    v, f = body
    rng = np.random.default_rng(3)
    pts = _sample_points(v, f, 2000, rng, near=0.03)
    sd = MeshBVH(v, f).signed_distance(pts)
    keep = np.abs(sd) > 1e-3
    inside = trimesh.Trimesh(v, f, process=False).contains(pts[keep])
    np.testing.assert_array_equal(sd[keep] < 0, inside)


def test_sign_on_sharp_edges_and_corners():
    """Points in the edge/vertex Voronoi regions of a box, where a face normal alone can give
    the wrong sign: only the pseudonormals get these right."""
    v, f = _box((1.0, 1.0, 1.0))
    bvh = MeshBVH(v, f)
    d = 0.1
    out = np.array([[0.5 + d, 0.5 + d, 0.0], [0.5 + d, 0.5 + d, 0.5 + d], [-0.5 - d, 0.0, 0.5 + d],
                    [0.5 + d, -0.5 - d, -0.5 - d]])
    sd = bvh.signed_distance(out)
    exp = np.linalg.norm(np.maximum(np.abs(out) - 0.5, 0.0), axis=1)
    np.testing.assert_allclose(sd, exp, atol=1e-12)
    inside = np.array([[0.45, 0.45, 0.0], [0.45, 0.45, 0.45], [0.0, 0.0, 0.0], [-0.49, 0.3, 0.1]])
    np.testing.assert_allclose(bvh.signed_distance(inside),
                               -(0.5 - np.abs(inside)).min(axis=1), atol=1e-12)


def test_sphere_signed_distance_within_sag():
    r = 0.3
    v, f = _sphere(r, 4)
    tri = v[f]
    # inscribed radius: the nearest face plane to the centre
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    r_in = np.abs(np.einsum("ij,ij->i", n / np.linalg.norm(n, axis=1, keepdims=True),
                            tri[:, 0])).min()
    rng = np.random.default_rng(4)
    dirs = rng.normal(size=(5000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    rad = rng.uniform(0.02, 0.6, (5000, 1))
    pts = dirs * rad
    sd = MeshBVH(v, f).signed_distance(pts)
    ana = rad[:, 0] - r
    # the polytope lies between the spheres r_in and r, so |p|-r <= sd <= |p|-r_in
    assert np.all(sd >= ana - 1e-12)
    assert np.all(sd <= ana + (r - r_in) + 1e-12)
    assert r - r_in < 2e-3


@pytest.mark.parametrize("name", ["icosphere", "body"])
def test_linear_velocity_field_reproduced(name, body):
    v, f = _mesh(name, body)
    rng = np.random.default_rng(5)
    A = rng.normal(size=(3, 3))
    b = rng.normal(size=3)
    vel = v @ A.T + b
    bvh = MeshBVH(v, f, vertex_velocities=vel)
    pts = _sample_points(v, f, 2000, rng)
    _, cp, _, face, bary = bvh.closest(pts)
    np.testing.assert_allclose(bvh.velocity_at(pts), cp @ A.T + b, atol=1e-11)
    np.testing.assert_allclose(bvh.velocity_at(face=face, bary=bary), cp @ A.T + b, atol=1e-11)
    col = ObjectSpaceCollider(v, f, tolerance=0.01, vertex_velocities=vel)
    status, _, bv, _ = col.query(pts)
    np.testing.assert_allclose(bv, cp @ A.T + b, atol=1e-11)
    # no velocities: zeros
    assert np.all(MeshBVH(v, f).velocity_at(pts[:10]) == 0.0)


def _rot(angle, axis):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def test_refit_equals_rebuild(body):
    v, f = body
    rng = np.random.default_rng(6)
    R = _rot(0.7, (0.3, 1.0, 0.2))
    t = np.array([0.2, -0.1, 0.5])
    v2 = v @ R.T + t
    vel2 = rng.normal(size=v.shape)
    refit = MeshBVH(v, f)
    refit.update(v2, vel2)
    fresh = MeshBVH(v2, f, vel2)
    # every node box holds its subtree after the refit
    tri = v2[f]
    leaf = refit.node_n > 0
    for i in np.flatnonzero(leaf)[::50]:
        a, n = refit.node_a[i], refit.node_n[i]
        tt = tri[refit.prim[a:a + n]].reshape(-1, 3)
        assert np.all(tt >= refit.node_lo[i] - 1e-15) and np.all(tt <= refit.node_hi[i] + 1e-15)
    pts = _sample_points(v2, f, 3000, rng)
    d1, c1, n1, _, _ = refit.closest(pts)
    d2, c2, n2, _, _ = fresh.closest(pts)
    np.testing.assert_allclose(d1, d2, atol=1e-12)
    np.testing.assert_allclose(refit.signed_distance(pts), fresh.signed_distance(pts), atol=1e-12)
    np.testing.assert_allclose(c1, c2, atol=1e-9)      # ties may pick the other triangle
    np.testing.assert_allclose(n1, n2, atol=1e-6)
    np.testing.assert_allclose(refit.velocity_at(pts), fresh.velocity_at(pts), atol=1e-9)
    # and the moved answers are the old ones moved: distances are rigid-invariant
    d0 = MeshBVH(v, f).closest((pts - t) @ R)[0]
    np.testing.assert_allclose(d1, d0, atol=1e-12)


def test_collider_status_and_depth():
    r, tol = 0.3, 0.01
    v, f = _sphere(r, 5)
    col = ObjectSpaceCollider(v, f, tolerance=tol)
    rng = np.random.default_rng(7)
    dirs = rng.normal(size=(600, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    # radial offsets from the sphere well clear of the polygon sag (< 0.2 mm at 5 subdivisions)
    off = np.repeat([0.03, 0.005, -0.004, -0.05], 150)
    pts = dirs * (r + off)[:, None]
    status, normal, vel, depth = col.query(pts)
    assert status.dtype == np.int8 and depth.dtype == np.float64
    exp = np.where(off >= tol, CLEAR, np.where(off >= 0, BAND, INSIDE))
    np.testing.assert_array_equal(status, exp)
    sd = col.bvh.signed_distance(pts)
    np.testing.assert_allclose(depth, tol - sd, atol=1e-15)
    assert np.all((depth > 0) == (status > 0))
    np.testing.assert_allclose(depth, tol - off, atol=5e-4)
    assert np.all(np.einsum("ij,ij->i", normal, dirs) > 0.999)     # outward, smooth
    assert np.all(vel == 0.0)
    # buffers are reused between calls of the same size
    s2, n2, v2, d2 = col.query(pts * 1.0)
    assert s2 is status and n2 is normal and v2 is vel and d2 is depth
    # search radius: far points are clear with the bound, near ones unchanged
    colr = ObjectSpaceCollider(v, f, tolerance=tol, max_distance=0.02)
    s3, n3, _, d3 = colr.query(pts)
    far = np.abs(off) > 0.02
    np.testing.assert_array_equal(s3[~far], exp[~far])
    np.testing.assert_allclose(d3[~far], depth[~far], atol=1e-15)
    assert np.all(s3[far] == CLEAR) and np.allclose(d3[far], tol - 0.02)
    assert np.all(n3[far] == 0.0)


def test_a_collider_that_answers_rows_answers_them_as_a_full_query_does():
    """RowsObjectSpaceCollider.query_rows (the exact finish's collider: the solver's carried
    answers ask it for some points alone) writes those rows as the full query would, and leaves
    the others' rows as they were."""
    from engine.collide.bvh import RowsObjectSpaceCollider

    r, tol = 0.3, 0.01
    v, f = _sphere(r, 4)
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    pts = dirs * (r + rng.uniform(-0.03, 0.03, 200))[:, None]
    full = [a.copy() for a in ObjectSpaceCollider(v, f, tolerance=tol).query(pts)]
    col = RowsObjectSpaceCollider(v, f, tolerance=tol)
    assert col.answers_rows
    col.query(pts + 1.0)  # (every row answered for other points first)
    before = [a.copy() for a in (col.status, col.normal, col.velocity, col.depth)]
    rows = np.array([5, 17, 100, 3, 0, 0], dtype=np.int64)
    out = col.query_rows(pts, rows, 4)
    k = rows[:4]
    for got, want, old in zip(out, full, before):
        np.testing.assert_array_equal(got[k], want[k])
        rest = np.setdiff1d(np.arange(200), k)
        np.testing.assert_array_equal(got[rest], old[rest])


def test_max_distance_in_mesh_queries():
    v, f = _sphere(0.3, 3)
    bvh = MeshBVH(v, f)
    pts = np.array([[0.0, 0.0, 0.31], [0.0, 0.0, 0.5], [0.0, 0.0, 0.0]])
    d, cp, _, face, _ = bvh.closest(pts, max_distance=0.05)
    assert face[0] >= 0 and face[1] == -1 and face[2] == -1
    assert np.isinf(d[1]) and np.isnan(cp[1]).all()
    exact = bvh.closest(pts)[0]
    assert d[0] == exact[0]
    assert np.isinf(bvh.signed_distance(pts, max_distance=0.05)[2])


def test_penetration_stats():
    r = 0.3
    v, f = _sphere(r, 4)
    rng = np.random.default_rng(8)
    dirs = rng.normal(size=(1000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    rad = np.full(1000, r + 0.02)
    rad[:5] = r - np.array([0.001, 0.002, 0.003, 0.004, 0.01])    # 0.5 % inside
    st = penetration_stats(v, f, dirs * rad[:, None])
    assert st["count_inside"] == 5 and st["count"] == 1000
    assert st["p99"] == 0.0                                       # fewer than 1 % inside
    assert abs(st["max"] - 0.01) < 1e-3 and 0.003 < st["mean"] < 0.006
    rad[:50] = r - 0.01                                          # 5 % inside
    st = penetration_stats(v, f, dirs * rad[:, None], bvh=MeshBVH(v, f))
    assert st["count_inside"] == 50 and abs(st["p99"] - 0.01) < 1e-3


def test_penetration_is_not_fooled_by_a_fold_turned_inside_out():
    """A walking scan's skin can fold inside out (behind the sample scan's bent knees, its
    weights fitted from the default body): the pseudonormal sign then puts points in the air "inside"
    (measured: 46-98 mm deep, 5-8 cm from any body vertex; 0 by winding number and by ray
    parity). Here a small box with its faces reversed beside a sphere: points just outside it
    read inside to the sign, and penetration_stats counts them outside by winding number; the
    points really inside the sphere still count."""
    from engine.collide.bvh import WINDING_CHECK, winding_numbers

    r = 0.3
    v, f = _sphere(r, 4)
    bv, bf = _box((0.1, 0.1, 0.1))
    bv = bv + np.array([0.6, 0.0, 0.0])
    v2 = np.vstack([v, bv])
    f2 = np.vstack([f, bf[:, ::-1] + len(v)])                  # the box inside out
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(WINDING_CHECK - 10, 3))  # all asked again (the deepest WINDING_CHECK are)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    near_box = np.array([0.6, 0.0, 0.0]) + dirs * 0.09         # outside the box, 4+ cm from it
    m = len(near_box)
    inside = dirs[:5] * (r - 0.01)                              # 1 cm inside the sphere
    pts = np.vstack([near_box, inside])
    sd = MeshBVH(v2, f2).signed_distance(pts)
    assert (sd[:m] < 0).sum() > 0.7 * m                         # the sign is fooled
    st = penetration_stats(v2, f2, pts)
    assert st["count_inside"] == 5 and st["outside_by_winding"] == int((sd[:m] < 0).sum())
    assert abs(st["max"] - 0.01) < 1e-3
    np.testing.assert_allclose(winding_numbers(v2, f2, pts), _winding(pts, v2[f2]), atol=1e-9)


def test_bad_input():
    v, f = _sphere(0.3, 1)
    with pytest.raises(ValueError):
        MeshBVH(v, f + len(v))
    bvh = MeshBVH(v, f)
    with pytest.raises(ValueError):
        bvh.update(v[:-1])
