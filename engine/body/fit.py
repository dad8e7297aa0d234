"""Give a scan the default body's skeleton and skinning weights, so that it can walk.

    rigged = fit_rig(scan)            # scan: a normalised Body without a rig

1. The template: the default body of the scan's stature (female unless `preset` says male).
2. Its arms are posed like the scan's: the direction of each scan arm (a line fitted to the scan
   points beside the torso, between the crotch and the shoulders) is given to the template's
   upper arm and forearm (rotations about the shoulder and elbow joints).
3. The posed template is mapped onto the scan from landmarks (engine.body.measure): heights
   piecewise-linearly through floor, knee, crotch, hip, waist, bust, shoulder and top of the head;
   widths and depths scaled by the ratio of the circumferences at the nearest landmark (hips,
   waist, bust; the legs take the hips', the head none).
4. Joints: the template's posed joints, mapped the same way. Weights and segment labels: each
   scan vertex takes those of the nearest mapped template vertex whose normal faces the same way
   (so a torso side under an arm hanging close to it does not take the arm's).
5. Below the waist the weights are smoothed over the scan's surface (smooth_weights: one
   implicit step of heat diffusion, SMOOTH_LENGTH): the nearest template vertex jumps between
   neighbouring scan vertices wherever the mapped template is off the scan by more than the
   scan's edges (13 mm median on the sample scan), and those jumps fold the skin when a joint
   bends (the sample scan's knees and groin crumpled while walking, and the cloth showed them).
   Above the waist they stay as transferred (the shoulders, which engine.scene.arms turns).

Limits: a scan in a very different pose (crossed legs, arms touching the torso) gets wrong
weights where limbs touch; the scan must be normalised (Y up, facing +Z, feet on y = 0:
engine.body.load).
"""

from __future__ import annotations

import numpy as np

from engine.body.motion import pose_joints
from engine.body.rig import joint_matrices, _skin_kernel
from engine.body.types import Body, Rig
from engine.errors import InputError


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction a to direction b (3x3)."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    s = float(np.linalg.norm(v))
    if s < 1e-9:
        return np.eye(3) if c > 0 else -np.eye(3)
    k = v / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * kx + (1 - c) * (kx @ kx)


def scan_arm_directions(scan: Body, m) -> dict[str, np.ndarray]:
    """Unit direction (shoulder -> hand) of each arm of the scan: the main axis of the scan's
    points well outside the torso, between the crotch and the shoulders."""
    v = scan.vertices
    half = 0.5 * m.shoulder_width
    out = {}
    for side, sign in (("L", 1.0), ("R", -1.0)):
        sel = (sign * v[:, 0] > half + 0.06) & (v[:, 1] > m.crotch_height) & (v[:, 1] < m.shoulder_height)
        if sel.sum() < 50:
            raise InputError(f"cannot find the scan's {'left' if sign > 0 else 'right'} arm away from the torso: "
                             "the walk needs a scan in an A-pose (arms apart from the body)")
        p = v[sel]
        c = p.mean(axis=0)
        _, _, vt = np.linalg.svd(p - c, full_matrices=False)
        d = vt[0]
        if d[1] > 0:  # shoulder -> hand points down
            d = -d
        out[side] = d
    return out


def _landmarks(m) -> tuple[list[float], list[str]]:
    names = ["knee_height", "crotch_height", "hip_height", "waist_height", "bust_height", "shoulder_height", "height"]
    ys = [getattr(m, n) for n in names]
    return ys, names


def _height_map(src, dst):
    """Piecewise-linear y mapping through matching landmark heights (and the floor)."""
    ys, names = _landmarks(src)
    yd, _ = _landmarks(dst)
    pairs = [(0.0, 0.0)] + [(a, b) for a, b, n in zip(ys, yd, names) if np.isfinite(a) and np.isfinite(b)]
    pairs.sort()
    xs = np.array([p[0] for p in pairs])
    ys2 = np.array([p[1] for p in pairs])
    if np.any(np.diff(xs) <= 0) or np.any(np.diff(ys2) <= 0):
        raise InputError("the scan's landmark heights are out of order (knee, crotch, hips, waist, bust, shoulders); "
                         "is it standing upright, feet on the floor?")

    def f(y):
        scale = ys2[-1] / xs[-1]
        return np.where(y > xs[-1], y * scale, np.interp(y, xs, ys2))
    return f


def _width_scale(src, dst):
    """Horizontal scale per height: the circumference ratio at the nearest landmark."""
    def ratio(a, b):
        r = b / a if (np.isfinite(a) and np.isfinite(b) and a > 0) else 1.0
        return float(np.clip(r, 0.6, 1.8))
    hips, waist, bust = ratio(src.hips, dst.hips), ratio(src.waist, dst.waist), ratio(src.bust, dst.bust)
    ys = np.array([src.crotch_height, src.hip_height, src.waist_height, src.bust_height, src.shoulder_height,
                   src.shoulder_height + 0.08])
    rs = np.array([hips, hips, waist, bust, bust, 1.0])
    ok = np.isfinite(ys)

    def f(y):
        return np.interp(y, ys[ok], rs[ok])
    return f


def fit_rig(scan: Body, preset: str = "female") -> Body:
    """A copy of `scan` with a Rig and segment labels fitted from the default body."""
    from scipy.spatial import cKDTree

    from engine.body.default import default_body
    from engine.body.measure import measure

    if scan.rig is not None:
        return scan
    h = scan.height
    if not (1.40 <= h <= 2.10):
        raise InputError(f"the scan is {h:.2f} m tall; fitting a skeleton needs a standing adult of 1.40 .. 2.10 m")
    tmpl = default_body(preset, height=h)
    rig = tmpl.rig
    ms = measure(scan)
    # 2. pose the template's arms like the scan's. Two ways, the one that fits the scan better
    # is kept (the 95th percentile of the distances from the scan's vertices to the mapped
    # template): (a) the template's upper arm and forearm turned onto the axis of the scan's
    # surface beside the torso; (b) the template's arm turned by the difference between that
    # axis and the same axis of its own surface, keeping its elbow. Measured: default:female
    # saved as a scan, (a) turned its upper arms 34 degrees (the surface's axis is that far from
    # the joint line) and left the hands 12 cm off (95 %: 120 mm), (b) fits it exactly; the
    # sample scan, (a) 53 mm, (b) 79 mm
    idx = {n: i for i, n in enumerate(rig.joint_names)}
    rest = rig.rest_transforms
    dirs = scan_arm_directions(scan, ms)
    straight = {}
    for side in ("L", "R"):
        sh, el, wr = (rest[idx[f"{n}.{side}"], :3, 3] for n in ("upperarm01", "lowerarm01", "wrist"))
        d_up = _rotation_between(el - sh, dirs[side])
        fore = d_up @ (wr - el)
        straight[f"upperarm01.{side}"] = d_up
        straight[f"lowerarm01.{side}"] = d_up.T @ _rotation_between(fore, dirs[side]) @ d_up
    dirs_t = scan_arm_directions(tmpl, measure(tmpl))
    turned = {f"upperarm01.{side}": _rotation_between(dirs_t[side], dirs[side]) for side in ("L", "R")}
    c_s = _torso_centre(scan.vertices, scan.faces, ms)
    best = None
    for deltas in (straight, turned):
        tv, joints = _mapped_template(tmpl, deltas, ms, c_s)
        tree = cKDTree(tv)
        dist, _ = tree.query(scan.vertices)
        if best is None or np.percentile(dist, 95) < np.percentile(best[0], 95):
            best = (dist, tv, tree, joints)
    _, tv, tree, joints = best
    # 4. weights and segments from the nearest mapped template vertex facing the same way
    dist, near = _nearest_facing(tv, tmpl.faces, scan, tree)
    # 5. smoothed below the waist, where the walk bends the body most (hips, knees)
    waist = ms.waist_height if np.isfinite(ms.waist_height) else SMOOTH_BELOW * h
    idx_s, w_s = smooth_weights(scan.vertices, scan.faces, rig.skin_indices[near], rig.skin_weights[near],
                                where=scan.vertices[:, 1] < waist)
    new_rig = Rig(joint_names=list(rig.joint_names), parents=rig.parents.copy(), rest_transforms=joints,
                  skin_indices=idx_s.astype(rig.skin_indices.dtype), skin_weights=w_s.astype(rig.skin_weights.dtype))
    notes = list(scan.notes) + [f"skeleton and weights fitted from the default {preset} body "
                                f"(median distance scan -> template {np.median(dist) * 1000:.0f} mm, "
                                f"95 % {np.percentile(dist, 95) * 1000:.0f} mm)"]
    return Body(vertices=scan.vertices, faces=scan.faces, name=scan.name, segments=tmpl.segments[near].copy(),
                rig=new_rig, notes=notes, to_world=scan.to_world)


SMOOTH_LENGTH = 0.04  # m: the length over which transferred weights are smoothed (smooth_weights)
SMOOTH_DROP = 1e-4  # ... and the smallest weight kept after it
SMOOTH_BELOW = 0.6  # ... below the waist; this x the height where the waist was not measured


def smooth_weights(vertices: np.ndarray, faces: np.ndarray, indices: np.ndarray, weights: np.ndarray,
                   length: float = SMOOTH_LENGTH, where: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Skinning weights (indices, weights: (N, K) joints and weights per vertex) smoothed over
    the mesh's surface: one backward-Euler step of heat diffusion, (M + t D L) W = M W0 with
    t = length^2 / 2, M the lumped vertex areas, L the cotangent Laplacian with negative
    cotangents taken as 0 (so every smoothed weight stays a convex mix of the given ones) and D
    the vertices to smooth (`where`; None: all -- the others keep their weights and hold their
    neighbours' as a boundary does), solved for every joint at once with a sparse LU. Then each
    vertex keeps its K largest weights (those above SMOOTH_DROP), renormalised.
    Measured on the sample scan (23,752 vertices, 0.2 s), skin edges folded past 90 degrees
    while walking (faces within 45 degrees of each other at rest; every 2nd frame of 2 s):
    1,220 as transferred (75 in the worst frame: knees, groin, elbows, armpits); smoothed
    everywhere 16 (at 2 cm 85, at 5 cm none), below the waist (fit_rig) 69, 53 of them at the
    armpits. Smoothed everywhere, the shoulders' weights spread down the torso's sides as well:
    with its arms lowered 30 degrees the scan measured 1.6 cm less round the bust (0.8 as
    transferred) and the dress on default:female saved as a scan with its arms lowered was
    left 7.3 % stretched between arm and torso (6.6-6.8 %): fit_rig keeps the transferred
    weights above the waist. default:female with its own weights has 61 (knees, feet).
    A 380,000-vertex mesh takes ~8 s and 1.7 GB."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    n, k_max = len(vertices), indices.shape[1]
    used, col = np.unique(indices, return_inverse=True)
    w0 = np.zeros((n, len(used)))
    np.add.at(w0, (np.repeat(np.arange(n), k_max), col.ravel()), weights.ravel())
    v, f = np.asarray(vertices, np.float64), np.asarray(faces)
    rows, cols, vals = [], [], []
    area2 = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    for c in range(3):  # the corner opposite edge (i, j)
        i, j, o = f[:, c], f[:, (c + 1) % 3], f[:, (c + 2) % 3]
        a, b = v[i] - v[o], v[j] - v[o]
        w = np.clip(0.5 * np.einsum("ij,ij->i", a, b) / np.maximum(area2, 1e-20), 0.0, 1e4)
        rows += [i, j]
        cols += [j, i]
        vals += [w, w]
    off = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    lap = sp.diags(np.asarray(off.sum(axis=1)).ravel()) - off
    mass = np.maximum(sum(np.bincount(f[:, c], area2 / 6.0, n) for c in range(3)), 1e-12)
    if where is not None:  # the other vertices keep their weights (rows of M alone)
        lap = sp.diags(np.asarray(where, np.float64)) @ lap
    smoothed = splu((sp.diags(mass) + 0.5 * length * length * lap).tocsc()).solve(mass[:, None] * w0)
    top = np.argsort(-smoothed, axis=1)[:, :k_max]
    w = np.take_along_axis(smoothed, top, axis=1)
    w = np.where(w > SMOOTH_DROP, w, 0.0)
    w /= w.sum(axis=1, keepdims=True)
    return used[top], w


NEAREST_K = 16  # candidates for the nearest template vertex facing the same way
FACING = 0.0  # ... whose normal's dot product with the scan vertex's normal exceeds this


def _nearest_facing(tv: np.ndarray, tf: np.ndarray, scan: Body, tree) -> tuple[np.ndarray, np.ndarray]:
    """(distance, index) of the nearest of the NEAREST_K nearest mapped template vertices whose
    normal faces the same way as the scan vertex's (dot > FACING); the nearest where none does.
    Where an arm hangs close to the torso, the nearest template vertex of a torso side under the
    armpit can be on the inner arm: measured on default:female as a scan with its arms lowered 30
    degrees (2.4 cm from the torso), the torso side then took upper-arm weights, and raising
    the arms pulled it out into flaps."""
    dist, near = tree.query(scan.vertices, k=NEAREST_K)
    tn = Body(tv, tf).vertex_normals()
    agree = np.einsum("nkc,nc->nk", tn[near], scan.vertex_normals()) > FACING
    first = np.where(agree.any(axis=1), agree.argmax(axis=1), 0)
    rows = np.arange(len(near))
    return dist[rows, first], near[rows, first]


def _mapped_template(tmpl: Body, deltas: dict, ms, c_s: np.ndarray):
    """The template posed with `deltas` (joint name -> rotation) and mapped onto the scan of
    measurements ms and torso centre c_s (step 3 of the module doc): (mapped vertices, mapped
    joint transforms)."""
    from engine.body.measure import measure

    rig = tmpl.rig
    g = pose_joints(rig, deltas)
    posed = np.empty_like(tmpl.vertices)
    _skin_kernel(tmpl.vertices, np.ascontiguousarray(rig.skin_indices, np.int32),
                 np.ascontiguousarray(rig.skin_weights, np.float64), joint_matrices(rig, g), posed)
    mt = measure(Body(posed, tmpl.faces))
    # 3. map the posed template onto the scan
    fy, fw = _height_map(mt, ms), _width_scale(mt, ms)
    # both centres the same way, from horizontal cuts of the torso: a scan is centred on its
    # bounding box, which its hands pull forward (default:female saved as a scan: the torso 8.7 cm
    # behind z = 0, every vertex mapped that far off -- median 42 mm -- and the walk tore the
    # arms, whose vertices took the torso's weights)
    c_t = _torso_centre(posed, tmpl.faces, mt)

    def mapped(p):
        q = np.empty_like(p)
        s = fw(p[:, 1])
        q[:, 0] = (p[:, 0] - c_t[0]) * s + c_s[0]
        q[:, 2] = (p[:, 2] - c_t[2]) * s + c_s[2]
        q[:, 1] = fy(p[:, 1])
        return q

    joints = g.copy()
    joints[:, :3, 3] = mapped(g[:, :3, 3])
    return mapped(posed), joints


def _torso_centre(v: np.ndarray, f: np.ndarray, m) -> np.ndarray:
    """(x, 0, z) centre of the torso: the mean x and the middle of the z range of the torso's
    horizontal cuts every 2 cm from the crotch to the armpits (the longest piece of each cut);
    the bounding box's centre (0, 0, 0 for a normalised body) when they were not measured."""
    from engine.body.measure import slice_stack

    if not (np.isfinite(m.crotch_height) and np.isfinite(m.armpit_height)):
        return np.zeros(3)
    ys = np.arange(m.crotch_height + 0.02, m.armpit_height - 0.02, 0.02)
    pts = [max(pieces, key=lambda p: p.length).points for pieces in slice_stack(v, f, ys) if pieces]
    if not pts:
        return np.zeros(3)
    p = np.concatenate(pts)
    return np.array([p[:, 0].mean(), 0.0, 0.5 * (p[:, 1].min() + p[:, 1].max())])
