"""Give a scan the default body's skeleton and skinning weights, so that it can walk.

    rigged = fit_rig(scan)            # scan: a normalised Body without a rig

1. The template: the default body of the scan's sex (engine.body.sex, unless `preset` says)
   and stature, and of the build (weight, muscle) whose girths are closest to the scan's
   (closest_build).
2. Its arms are posed like the scan's (fit_arms): the upper arm and forearm turned about the
   shoulder and the elbow until the template's arm lies closest to the scan's.
3. The posed template is mapped onto the scan from landmarks (engine.body.measure): heights
   piecewise-linearly through floor, knee, crotch, hip, waist, bust, shoulder and top of the head;
   widths and depths scaled by the ratio of the circumferences at the nearest landmark (hips,
   waist, bust; the legs take the hips', the head none).
4. Joints: the template's posed joints, mapped the same way. Weights and segment labels: each
   scan vertex takes those of the nearest mapped template vertex whose normal faces the same way
   (so a torso side under an arm hanging close to it does not take the arm's).
5. Below the waist and along the arms past the shoulders the weights are smoothed over the
   scan's surface (smooth_weights: one implicit step of heat diffusion, SMOOTH_LENGTH): the
   nearest template vertex jumps between neighbouring scan vertices wherever the mapped
   template is off the scan by more than the scan's edges (13 mm median on the sample scan),
   and those jumps fold the skin when a joint bends (the sample scan's knees and groin crumpled while walking, and the cloth showed them).
   The shoulders and the torso above the waist keep them as transferred (engine.scene.arms
   turns the shoulders).

Limits: a scan in a very different pose (crossed legs, arms pressed into the torso) gets wrong
weights where limbs touch; the scan must be normalised (Y up, facing +Z, feet on y = 0:
engine.body.load).
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from engine.body.motion import pose_joints
from engine.body.rig import joint_matrices, _skin_kernel
from engine.body.types import Body, Rig
from engine.errors import InputError


def _landmarks(m) -> tuple[list[float], list[str]]:
    names = ["knee_height", "crotch_height", "hip_height", "waist_height", "bust_height", "shoulder_height", "height"]
    ys = [getattr(m, n) for n in names]
    return ys, names


def _height_map(src, dst):
    """Piecewise-linear y mapping through matching landmark heights (and the floor): the
    landmarks in order (_landmarks), each kept where it is above the last kept one on both
    bodies (a landmark out of order on one of them -- a seat measured under the crotch -- is
    left out rather than fold the map)."""
    ys, _ = _landmarks(src)
    yd, _ = _landmarks(dst)
    xs, ys2 = [0.0], [0.0]
    for a, b in zip(ys, yd):
        if np.isfinite(a) and np.isfinite(b) and a > xs[-1] + 1e-3 and b > ys2[-1] + 1e-3:
            xs.append(float(a))
            ys2.append(float(b))
    if len(xs) < 4:
        raise InputError("the scan's landmark heights (knee, crotch, hips, waist, bust, shoulders) could not be "
                         "matched with the default body's; is it standing upright, feet on the floor?")
    xs, ys2 = np.array(xs), np.array(ys2)

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


_FITTED: "OrderedDict[tuple, Body]" = OrderedDict()
FITTED_KEPT = 4  # scans whose fitted rig is kept (a try-on fits one 2-3 times: sleeves, arms, walk)


def fit_rig(scan: Body, preset: str | None = None) -> Body:
    """A copy of `scan` with a Rig and segment labels fitted from the default body (module
    doc). preset: 'female' / 'male' to choose the template; None reads the sex from the scan's
    shape (engine.body.sex). The result is kept for the last FITTED_KEPT scans (by the mesh's
    content), so that asking again costs nothing."""
    from engine.body.measure import _digest, measure
    from engine.body.sex import body_sex, sex_note

    if scan.rig is not None:
        return scan
    h = scan.height
    if not (1.40 <= h <= 2.10):
        raise InputError(f"the scan is {h:.2f} m tall; fitting a skeleton needs a standing adult of 1.40 .. 2.10 m")
    ms = measure(scan)
    if {"crotch height", "armpit height", "shoulder height"} <= set(ms.estimated):
        # no landmark of a person found (a capsule, a box): refused before the build search's
        # seconds, which would only end in the refusal below
        raise InputError("the default skeleton does not fit this body: neither its crotch, its armpits nor its "
                         f"shoulders were found ({'; '.join(ms.notes)}); it should be a standing person, legs apart "
                         "and arms apart from the body")
    notes = []
    if preset is None:
        preset = body_sex(scan, ms)
        notes = [n for n in [sex_note(scan, ms)] if n]
    key = (_digest(scan), preset)
    if key in _FITTED:
        _FITTED.move_to_end(key)
        return _copy(_FITTED[key], scan)
    fitted = _fit(scan, ms, preset, notes)
    _FITTED[key] = fitted
    while len(_FITTED) > FITTED_KEPT:
        _FITTED.popitem(last=False)
    return _copy(fitted, scan)


def _copy(fitted: Body, scan: Body) -> Body:
    return Body(vertices=scan.vertices, faces=scan.faces, name=scan.name, segments=fitted.segments.copy(),
                rig=fitted.rig, notes=list(fitted.notes), to_world=scan.to_world)


def _fit(scan: Body, ms, preset: str, notes: list[str]) -> Body:
    from scipy.spatial import cKDTree

    from engine.body.default import default_body
    from engine.body.measure import measure

    build = closest_build(scan, ms, preset)
    tmpl = default_body(preset, height=scan.height, **build)
    rig = tmpl.rig
    mt = measure(tmpl)
    c_s = _torso_centre(scan.vertices, scan.faces, ms)
    # 2. pose the template's arms like the scan's (fit_arms), 3. map it onto the scan
    deltas = fit_arms(tmpl, mt, scan, ms, c_s)
    tv, joints = _mapped_template(tmpl, deltas, ms, c_s)
    tree = cKDTree(tv)
    # 4. weights and segments from the nearest mapped template vertex facing the same way
    dist, near = _nearest_facing(tv, tmpl.faces, scan, tree)
    near = mend_islands(scan.vertices, scan.faces, tmpl.segments, near)
    if np.median(dist) > FIT_MEDIAN_MAX:
        why = "; ".join(ms.notes)
        raise InputError(f"the default skeleton does not fit this body: fitted, the default body is "
                         f"{np.median(dist) * 1000:.0f} mm from its surface (median; a scan of a person: under "
                         f"{FIT_MEDIAN_MAX * 1000:.0f}){f' ({why})' if why else ''}; it should be a standing person, "
                         "legs apart and arms apart from the body")
    # 5. smoothed below the waist, where the walk bends the body most (hips, knees)
    waist = ms.waist_height if np.isfinite(ms.waist_height) else SMOOTH_BELOW * scan.height
    idx_s, w_s = smooth_weights(scan.vertices, scan.faces, rig.skin_indices[near], rig.skin_weights[near],
                                where=(scan.vertices[:, 1] < waist) | _arm_below_shoulder(scan, tmpl, near, joints))
    new_rig = Rig(joint_names=list(rig.joint_names), parents=rig.parents.copy(), rest_transforms=joints,
                  skin_indices=idx_s.astype(rig.skin_indices.dtype), skin_weights=w_s.astype(rig.skin_weights.dtype))
    shape = ", ".join(f"{k} {v:g}" for k, v in build.items())
    notes = list(scan.notes) + notes + [f"skeleton and weights fitted from the default {preset} body ({shape}) "
                                        f"(median distance scan -> template {np.median(dist) * 1000:.0f} mm, "
                                        f"95 % {np.percentile(dist, 95) * 1000:.0f} mm)"]
    return Body(vertices=scan.vertices, faces=scan.faces, name=scan.name, segments=tmpl.segments[near].copy(),
                rig=new_rig, notes=notes, to_world=scan.to_world)


FIT_MEDIAN_MAX = 0.04  # m: a fit whose median distance to the scan is larger is refused (not a person)
SMOOTH_ARM_FROM = 0.12  # m from the shoulder joint: arm vertices further out are smoothed too


def _arm_below_shoulder(scan: Body, tmpl: Body, near: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(N,) bool: scan vertices labelled arm (from the template vertex `near` each) further than
    SMOOTH_ARM_FROM from their side's shoulder joint (upperarm01 in the mapped `joints`): the
    weights transferred there jump between the upper arm's joints and fold the skin when the
    arms swing."""
    from engine.body.types import SEGMENT_ID

    names = tmpl.rig.joint_names
    seg = tmpl.segments[near]
    out = np.zeros(len(scan.vertices), bool)
    for side, name in (("L", "left_arm"), ("R", "right_arm")):
        sh = joints[names.index(f"upperarm01.{side}"), :3, 3]
        mine = seg == SEGMENT_ID[name]
        out |= mine & (np.linalg.norm(scan.vertices - sh, axis=1) > SMOOTH_ARM_FROM)
    return out


# the default body's shape controls tried for a scan (closest_build): weight and muscle
BUILD_GRID = (0.0, 0.25, 0.5, 0.75, 1.0)
GIRTH_WINDOW = 0.04  # m above and below a landmark where its girth is looked for on a candidate


def closest_build(scan: Body, ms, preset: str) -> dict[str, float]:
    """{'weight': w, 'muscle': u} of the default `preset` body, at the scan's stature, whose
    bust, waist and hip girths are closest to the scan's (sum of squared log ratios; on both
    the largest / smallest / largest torso cut within GIRTH_WINDOW of the scan's landmark
    heights, _girths_near), over BUILD_GRID x BUILD_GRID (searched one control at a time). The
    averages (0.5, 0.5) where the scan's landmarks were not measured."""
    from engine.body.default import default_body

    heights = np.array([ms.bust_height, ms.waist_height, ms.hip_height])
    want = _girths_near(scan, heights) if np.isfinite(heights).all() else np.full(3, np.nan)
    if not np.isfinite(want).all():
        return {"weight": 0.5, "muscle": 0.5}
    costs: dict[tuple[float, float], float] = {}

    def cost(w, u):
        if (w, u) not in costs:
            cand = default_body(preset, height=scan.height, weight=w, muscle=u, cache=False)
            got = _girths_near(cand, heights)
            costs[(w, u)] = float(np.sum(np.log(got / want) ** 2)) if np.isfinite(got).all() else np.inf
        return costs[(w, u)]

    w, u = 0.5, 0.5
    for _ in range(2):  # one control after the other, twice
        w = min(BUILD_GRID, key=lambda x: cost(x, u))
        u = min(BUILD_GRID, key=lambda x: cost(w, x))
    return {"weight": w, "muscle": u}


def _girths_near(body: Body, heights: np.ndarray) -> np.ndarray:
    """(bust, waist, hips): the largest, smallest and largest convex-hull perimeter of the
    longest cut within GIRTH_WINDOW of each height."""
    from engine.body.measure import slice_stack

    out = []
    for k, y in enumerate(heights):
        ys = np.arange(y - GIRTH_WINDOW, y + GIRTH_WINDOW + 1e-9, 0.02)
        g = [max(p, key=lambda q: q.length).hull_perimeter for p in slice_stack(body.vertices, body.faces, ys) if p]
        out.append((min if k == 1 else max)(g) if g else np.nan)
    return np.array(out)


# the template's arm pose searched for a scan's (fit_arms), degrees from its rest pose: each arm
# turned out (+) in the frontal plane and back (+) about the shoulder, then the forearm the same
# about the elbow
ARM_GRIDS = (np.arange(-40.0, 51.0, 10.0), np.arange(-40.0, 41.0, 10.0),
             np.arange(-30.0, 31.0, 10.0), np.arange(-40.0, 41.0, 10.0))
ARM_CAP = 0.10  # m: a point's distance counts up to this (_arm_cost)
ARM_POINTS = 3000  # scan arm points per side compared (every k-th)
ARM_APART = 0.02  # m: a scan point this far from the template without its arms is an arm's


def fit_arms(tmpl: Body, mt, scan: Body, ms, c_s: np.ndarray) -> dict[str, np.ndarray]:
    """Joint rotations (fit_rig's `deltas`) that pose the template's arms like the scan's: for
    each arm two angles at a time over their grids (ARM_GRIDS: the upper arm out and back, then
    the upper arm and forearm back -- alone, the upper arm went back to make up for the default
    body's forearm reaching forward, the elbow bent back --, then the forearm out and back),
    whichever brings the mapped template closest to the scan on that side (_arm_cost), then each
    angle refined to 1 degree. Scans come in any pose from arms down (hands on the thighs) to a
    T-pose, in the frontal plane or reaching forward (as the default body's do); with the arms
    down there is no surface beside the torso to take an arm's axis from."""
    from scipy.spatial import cKDTree

    arm = _arm_share(tmpl.rig)
    scan_tree = cKDTree(scan.vertices)
    c_t = _torso_centre(tmpl.vertices, tmpl.faces, mt)
    turns = {"L": [0.0] * 4, "R": [0.0] * 4}
    # the scan's points that the template without its arms does not explain: the scan's arms
    rest, _ = _mapped_template(tmpl, {}, ms, c_s, mt, c_t)
    armless = np.ones(len(rest), bool)
    armless[np.concatenate(list(arm.values()))] = False
    unexplained = cKDTree(rest[armless]).query(scan.vertices)[0] > ARM_APART
    for side, sign in (("L", 1.0), ("R", -1.0)):
        mine = scan.vertices[unexplained & (sign * (scan.vertices[:, 0] - c_s[0]) > 0)]
        mine = mine[::max(1, len(mine) // ARM_POINTS)]

        def cost(pairs, side=side, mine=mine):
            trial = {s: list(t) for s, t in turns.items()}
            for k, a in pairs:
                trial[side][k] = a
            tv, _ = _mapped_template(tmpl, _arm_deltas(trial), ms, c_s, mt, c_t, rows=arm[side])
            return _arm_cost(tv, mine, scan_tree)

        for k1, k2 in ((0, 1), (1, 3), (2, 3)):  # two angles at a time, over their grids
            _pair_search(cost, turns[side], k1, k2, ARM_GRIDS[k1], ARM_GRIDS[k2])
        for k1, k2 in ((0, 1), (1, 3), (2, 3)):  # again, 5 degrees about where they are
            _pair_search(cost, turns[side], k1, k2, *(turns[side][k] + np.arange(-10.0, 11.0, 5.0) for k in (k1, k2)))
        for step in (2.0, 1.0):
            for k in range(4):
                a0 = turns[side][k]
                turns[side][k] = min((a0 - step, a0, a0 + step), key=lambda a, k=k: cost([(k, a)]))
    return _arm_deltas(turns)


def _pair_search(cost, t: list, k1: int, k2: int, grid1, grid2) -> None:
    """Set angles t[k1], t[k2] to the pair of grid1 x grid2 of least cost([(k1, a), (k2, b)])."""
    pairs = [(a, b) for a in grid1 for b in grid2]
    t[k1], t[k2] = min(pairs, key=lambda ab: cost([(k1, ab[0]), (k2, ab[1])]))


def _arm_deltas(turns: dict) -> dict[str, np.ndarray]:
    """Rotations of the upper arms and forearms by turns[side] = (upper out, upper back, fore
    out, fore back) degrees (back: about x, then out: about z, away from the body). Back
    first: an arm turned out level first has no way left to go back (about x it only twists),
    and SMPL's T-pose holds its arms 7 cm behind the default body's (its fit had left them
    hanging, the nearest pose the search could reach)."""
    from engine.body.motion import _rot

    out = {}
    for side, sign in (("L", 1.0), ("R", -1.0)):
        t = turns[side]
        up = _rot("z", sign * t[0]) @ _rot("x", t[1])
        out[f"upperarm01.{side}"] = up
        # (a child's delta is in the rest frame, before its parent's turn: conjugated)
        out[f"lowerarm01.{side}"] = up.T @ _rot("x", t[3]) @ _rot("z", sign * t[2]) @ up
    return out


def _arm_share(rig: Rig) -> dict[str, np.ndarray]:
    """side -> indices of the template vertices weighted mostly (> 0.5) to that arm's joints
    (the shoulder's descendants) but not to its fingers: the fingers' many vertices would have
    the search fit the hand and leave the elbow anywhere along the arm."""
    parents = rig.parents
    finger = np.array([n.startswith(("finger", "metacarpal")) for n in rig.joint_names])
    out = {}
    for side in ("L", "R"):
        root = rig.joint_names.index(f"shoulder01.{side}")
        inside = np.zeros(len(parents), bool)
        inside[root] = True
        for j in range(len(parents)):  # parents come before their children
            if parents[j] >= 0 and inside[parents[j]]:
                inside[j] = True
        share = (rig.skin_weights * inside[rig.skin_indices]).sum(axis=1)
        fingers = (rig.skin_weights * finger[rig.skin_indices]).sum(axis=1)
        out[side] = np.nonzero((share > 0.5) & (fingers < 0.5))[0]
    return out


def _arm_cost(a: np.ndarray, scan_arm: np.ndarray, scan_tree) -> float:
    """How far the mapped template's arm (its vertices a) is from the scan's on one side: the
    mean distance from its vertices to the scan's, plus the mean distance from the scan's arm
    points (scan_arm) to its vertices, each distance at most ARM_CAP."""
    from scipy.spatial import cKDTree

    d1, _ = scan_tree.query(a, distance_upper_bound=ARM_CAP)
    d2, _ = cKDTree(a).query(scan_arm, distance_upper_bound=ARM_CAP) if len(scan_arm) else (np.zeros(1), None)
    return float(np.minimum(d1, ARM_CAP).mean() + np.minimum(d2, ARM_CAP).mean())


SMOOTH_LENGTH = 0.05  # m: the length over which transferred weights are smoothed (smooth_weights)
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
    vertex keeps its K largest weights (those above SMOOTH_DROP), renormalised. fit_rig smooths
    below the waist and along the arms, not the shoulders and the torso above the waist (there
    the shoulders' weights spread down the torso's sides). A 380,000-vertex mesh takes ~8 s and
    1.7 GB (docs/tuning.md: the folds measured)."""
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


def mend_islands(vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray, near: np.ndarray) -> np.ndarray:
    """`near` (a template vertex for each scan vertex, whose segment `labels[near]` and weights the
    scan vertex takes) with every island mended: each segment (an arm, a leg, the torso, the
    head) is one connected piece of a body's surface, so a piece of a segment's vertices apart
    from its largest piece -- a hand lying on a thigh labelled leg, the torso's side under a
    pressed arm labelled arm -- takes the template vertex of the nearest vertex (along the
    surface) outside every such piece. Where limbs touch, the nearest template vertex is often
    the other limb's, and the skin there stayed behind when the arms were turned out (a sheet
    from the hand to the thigh; measured on the sample scan with its hands on the thighs)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components, dijkstra

    n = len(vertices)
    seg = labels[near]
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    same = seg[e[:, 0]] == seg[e[:, 1]]
    ones = np.ones(int(same.sum()))
    _, comp = connected_components(sp.coo_matrix((ones, (e[same, 0], e[same, 1])), shape=(n, n)), directed=False)
    island = np.zeros(n, bool)
    for s in np.unique(seg):
        mine = seg == s
        sizes = np.bincount(comp[mine])
        island[mine] = comp[mine] != np.argmax(sizes)
    if not island.any() or island.all():
        return near
    # the nearest vertex outside the islands, along the surface (edges into an island only)
    into = island[e[:, 0]] | island[e[:, 1]]
    length = np.linalg.norm(vertices[e[into, 0]] - vertices[e[into, 1]], axis=1) + 1e-9
    graph = sp.coo_matrix((length, (e[into, 0], e[into, 1])), shape=(n, n)).tocsr()
    sources = np.flatnonzero(~island & np.isin(np.arange(n), e[into].ravel()))
    if not len(sources):
        return near
    _, _, src = dijkstra(graph, directed=False, indices=sources, min_only=True, return_predecessors=True)
    out = near.copy()
    fix = island & (src >= 0)
    out[fix] = near[src[fix]]
    return out


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


def _mapped_template(tmpl: Body, deltas: dict, ms, c_s: np.ndarray, mt=None, c_t=None, rows=None):
    """The template posed with `deltas` (joint name -> rotation) and mapped onto the scan of
    measurements ms and torso centre c_s (step 3 of the module doc): (mapped vertices, mapped
    joint transforms). mt, c_t: the template's measurements and torso centre to map from
    (fit_arms gives those of the rest pose, the same for every trial); None: the posed
    template's own. rows: only these vertices (fit_arms' trials pose only the arm)."""
    from engine.body.measure import measure

    rig = tmpl.rig
    g = pose_joints(rig, deltas)
    sel = slice(None) if rows is None else rows
    v = np.ascontiguousarray(tmpl.vertices[sel])
    posed = np.empty_like(v)
    _skin_kernel(v, np.ascontiguousarray(rig.skin_indices[sel], np.int32),
                 np.ascontiguousarray(rig.skin_weights[sel], np.float64), joint_matrices(rig, g), posed)
    # 3. map the posed template onto the scan
    mt = mt if mt is not None else measure(Body(posed, tmpl.faces))
    fy, fw = _height_map(mt, ms), _width_scale(mt, ms)
    # both centres the same way, from horizontal cuts of the torso: a scan is centred on its
    # bounding box, which its hands pull forward (default:female saved as a scan: the torso 8.7 cm
    # behind z = 0, every vertex mapped that far off -- median 42 mm -- and the walk tore the
    # arms, whose vertices took the torso's weights)
    c_t = c_t if c_t is not None else _torso_centre(posed, tmpl.faces, mt)

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
