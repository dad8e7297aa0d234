"""Place flat panels around a body from its landmarks (catalogue garments, and patterns on a
body they were not made for).

Torso and hip panels are wrapped onto an elliptic cylinder around the body: at every height the
ellipse is the body's cross-section (torso and legs, never the arms) grown by a clearance and,
where the garment is wider than that, grown until the panel's width spans half of it; the
ellipses change slowly with height (wrap_torso); above the armholes the rows stand clear of
the shoulders and lean in toward the upper chest and the shoulder blades (_lean_in), so the
straps start close to meeting over the shoulders. A panel's
horizontal coordinate is laid out as arc length from the front (or back) centre line, so front and
back panels meet at the sides and the side seams start almost closed. Sleeves are wrapped onto tubes
around the arm's smoothed, elbow-bent centre line with their underarm seam underneath
(wrap_sleeve). Trouser panels wrap the torso
above the crotch and their own leg below it, blended over 10 cm (wrap_trousers, LegSections).
"""

from __future__ import annotations

import numpy as np

from engine.body.measure import slice_stack
from engine.body.types import SEGMENTS, Body
from engine.errors import InputError, TryonError
from engine.pattern.catalogue import arm_joints, chart_of
from engine.pattern.spec import PanelHint

CLEARANCE = 0.02  # m between the body and a freshly placed panel
ROW = 0.01  # m: wrap_torso finds the body's ellipse every ROW of a panel's height
SLOPE = 0.3  # see wrap_torso
RISE_SLOPE = 0.075  # see wrap_torso: how fast the straps' move out eases in below clamp_y
PROFILE_X = np.arange(-1.0, 1.0001, 0.01)  # m: the x bins of BodySections.surface_z


class BodySections:
    """Ellipses (centre x, z; semi-axes a, b) of the body without its arms, every 1 cm.
    cover: grow each ellipse until it contains the whole cut (fewer panel points start inside
    the body, at the price of side seams that start further apart); else the ellipse inscribed
    in the cut's bounding box."""

    def __init__(self, body: Body, cover: bool = False):
        v, f = body.vertices, body.faces
        if body.segments is not None:
            keep_seg = np.isin(body.segments, [SEGMENTS.index(s) for s in ("torso", "left_leg", "right_leg")])
            f = f[keep_seg[f].all(axis=1)]
        self.ys = np.arange(0.02, float(v[:, 1].max()), 0.01)
        cuts = slice_stack(v, f, self.ys)
        ell = np.full((len(self.ys), 5), np.nan)  # the 5th: how much `cover` grew the ellipse
        for k, pieces in enumerate(cuts):
            # scans: arms and hands hang beside the hips; keep pieces near the body axis
            pts = [p.points for p in pieces if abs(p.centroid[0]) < 0.2 or body.segments is not None]
            if not pts:
                continue
            p = np.concatenate(pts)
            if cover:
                ell[k] = _covering_ellipse(p)
            else:
                lo, hi = p.min(axis=0), p.max(axis=0)
                ell[k] = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2, 1.0]
        ok = np.isfinite(ell[:, 0])
        if ok.sum() < 10:
            raise InputError("could not find the body's cross-sections to place the garment")
        for c in range(5):  # fill gaps (e.g. a hole in a scan) by interpolation
            ell[:, c] = np.interp(self.ys, self.ys[ok], ell[ok, c])
        self.ell = ell
        self._v, self._f = body.vertices, body.faces  # the whole body, for surface_z
        self._profiles: dict = {}
        self._cuts: dict = {}  # row (1 cm) -> the body's cut there (both sides' profiles use it)

    def at(self, y: np.ndarray, grown: bool = False) -> np.ndarray:
        """(len(y), 4) ellipses at heights y (grown: (len(y), 5), + the growth factor of cover)."""
        return np.stack([np.interp(y, self.ys, self.ell[:, c]) for c in range(5 if grown else 4)], axis=1)

    def surface_z(self, x: np.ndarray, y: np.ndarray, side: float) -> np.ndarray:
        """The whole body's (arms included) frontmost z (side +1) or backmost z (side -1) within
        1 cm of each (x, y), from its cut at the nearest 1 cm; NaN where the body is not."""
        rows = np.round(np.asarray(y) / 0.01).astype(int)
        out = np.full(len(rows), np.nan)
        uniq = np.unique(rows)
        todo = [r for r in uniq if r not in self._cuts]
        if todo:  # the new cuts at once (slice_stack sorts the faces to the cuts once; each cut
            # alone cost 6.5 ms on the default body, 49 of them a third of the dress's placement)
            for r, pieces in zip(todo, slice_stack(self._v, self._f, np.array(todo) * 0.01)):
                self._cuts[r] = pieces
        for r in uniq:
            prof = self._profiles.get((r, side))
            if prof is None:
                pieces = self._cuts[r]
                prof = np.full(len(PROFILE_X), -np.inf)
                if pieces:
                    p = np.concatenate([q.points for q in pieces])
                    b = np.clip(np.round((p[:, 0] - PROFILE_X[0]) / 0.01).astype(int), 0, len(PROFILE_X) - 1)
                    np.maximum.at(prof, b, side * p[:, 1])
                    prof = np.maximum(prof, np.maximum(np.roll(prof, 1), np.roll(prof, -1)))  # within 1 cm
                self._profiles[(r, side)] = prof
            sel = rows == r
            b = np.clip(np.round((x[sel] - PROFILE_X[0]) / 0.01).astype(int), 0, len(PROFILE_X) - 1)
            out[sel] = np.where(np.isfinite(prof[b]), side * prof[b], np.nan)
        return out


def _covering_ellipse(p: np.ndarray) -> list[float]:
    """(cx, cz, a, b) of the ellipse centred on the bounding box of the (K, 2) points, with its
    axes' ratio, grown until it contains every point (the box's own inscribed ellipse cuts the
    corners off: the front of both thighs, the shoulder blades)."""
    lo, hi = p.min(axis=0), p.max(axis=0)
    c = (lo + hi) / 2
    a, b = max((hi[0] - lo[0]) / 2, 1e-3), max((hi[1] - lo[1]) / 2, 1e-3)
    k = max(1.0, float(np.sqrt((((p[:, 0] - c[0]) / a) ** 2 + ((p[:, 1] - c[1]) / b) ** 2).max())))
    return [c[0], c[1], a * k, b * k, k]


_TH = np.linspace(-np.pi, np.pi, 721)


def _ellipse_arc(a: float, b: float) -> np.ndarray:
    """Arc length from theta = 0 at each angle of _TH on the ellipse (a along x, b along z)."""
    return _ellipse_arcs(np.array([a]), np.array([b]))[0]


def _ellipse_arcs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """_ellipse_arc of each ellipse (a[i], b[i]) at once: (len(a), len(_TH))."""
    px, pz = a[:, None] * np.sin(_TH)[None, :], b[:, None] * np.cos(_TH)[None, :]
    dx, dz = px[:, 1:] - px[:, :-1], pz[:, 1:] - pz[:, :-1]
    seg = np.sqrt(dx * dx + dz * dz)
    arc = np.concatenate([np.zeros((len(a), 1)), np.cumsum(seg, axis=1)], axis=1)
    arc -= np.array([np.interp(0.0, _TH, row) for row in arc])[:, None]
    return arc


def _ellipse_point(a: float, b: float, s: np.ndarray, arc: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Angles theta (from +z toward +x) at arc lengths s from theta = 0 on the ellipse
    (a along x, b along z); returns (sin, cos). arc: _ellipse_arc(a, b), if made already."""
    t = np.interp(s, _ellipse_arc(a, b) if arc is None else arc, _TH)
    return np.sin(t), np.cos(t)


def _half_perimeter(a: float, b: float) -> float:
    h = ((a - b) / (a + b)) ** 2
    return 0.5 * np.pi * (a + b) * (1 + 3 * h / (10 + np.sqrt(4 - 3 * h)))  # Ramanujan


def wrap_torso(uv: np.ndarray, hint: PanelHint, sections: BodySections, top_y: float,
               outline: np.ndarray, widen_to: float | None = None, clamp_y: float | None = None,
               lean: bool = True) -> np.ndarray:
    """(n, 2) panel points (metres; v = 0 at the panel's top, u = 0 on its centre line) ->
    (n, 3) world points on the front (hint.side == 'front') or back of the body.
    outline: (M, 2) the panel's outline, for its width at each height; clamp_y: above this
    height use the cross-section at it (a top's shoulder straps go over the shoulders, not
    around the neck); lean: the rows above clamp_y lean in over the shoulders (_lean_in; a
    sleeved top's shoulders are held by its sleeve caps and stand straight up).
    The ellipses are found every ROW of the panel's height and a point lies between the two
    nearest (linear in height). A panel point keeps its height, so where the ellipse changes
    fast with height a vertical line of the panel is stretched: the body's own profile (under
    the bust, at the seat) strained the placed dress by up to 70 % and its springs kicked the
    hem up at metres per second. So the ellipses' extremes (front, back and sides) only move
    out until they change by at most SLOPE per metre of height, up and down:
    the cloth stands off where the body narrows, as a dress falls from the bust, and a
    vertical line is stretched by about sqrt(1 + SLOPE^2) - 1 at most (measured on the dress:
    structural springs max +70 % -> +27 %, p99 +28 % -> +14 %; slope 0.15 halves that again
    but starts the side seams up to 9 cm apart)."""
    u, v = uv[:, 0], uv[:, 1]
    y = top_y + v
    sign = 1.0 if hint.side == "front" else -1.0
    rows = np.arange(int(np.floor(v.min() / ROW)), int(np.floor(v.max() / ROW)) + 2)  # rows[-2] * ROW <= v.max()
    ell = np.zeros((len(rows), 4))  # cx, cz, a, b of each row
    yr = top_y + rows * ROW
    if clamp_y is not None:
        yr = np.minimum(yr, clamp_y)
    cuts = sections.at(yr, grown=True)
    widths = _widths_at(outline, np.clip(rows * ROW, v.min(), v.max()))
    for j in range(len(rows)):
        cx, cz, a, b, kc = cuts[j]
        a, b = a + CLEARANCE, b + CLEARANCE
        width = widths[j]
        half = _half_perimeter(a, b)
        # kc > 1 only for covering sections: a tighter garment shrinks them back toward the box
        # ellipse (halfway, in ratio) so that its side seams start (nearly) closed
        k = max(kc ** -0.5, width / half) if widen_to is None else max(kc ** -0.5, widen_to / half)
        ell[j] = cx, cz, a * k, b * k
    # the ellipses' extremes (left, right, front, back) move out until they change by at most
    # SLOPE a metre of height; the ellipse through them is used
    cx, cz, a, b = ell.T
    ext = _limit_slope(np.stack([cx + a, a - cx, cz + b, b - cz], axis=1), SLOPE * ROW)  # x max, -x min, ...
    ell = np.stack([(ext[:, 0] - ext[:, 1]) / 2, (ext[:, 2] - ext[:, 3]) / 2,
                    (ext[:, 0] + ext[:, 1]) / 2, (ext[:, 2] + ext[:, 3]) / 2], axis=1)
    f = v / ROW - rows[0]
    j0 = np.clip(np.floor(f).astype(int), 0, len(rows) - 2)
    w = np.clip(f - j0, 0.0, 1.0)
    out = np.zeros((len(uv), 3))
    facing = np.zeros(len(uv))  # cos of the angle round the ellipse: 1 facing front/back, 0 at the sides
    arcs = _ellipse_arcs(ell[:, 2], ell[:, 3])  # each row's ellipse serves the bands above and below it
    for j, sel in _groups(j0):
        for jj, wj in ((j, 1.0 - w), (j + 1, w)):
            cx, cz, a, b = ell[jj]
            sn, cs = _ellipse_point(a, b, u[sel], arcs[jj])
            out[sel, 0] += wj[sel] * (cx + a * sn)
            out[sel, 2] += wj[sel] * (cz + sign * b * cs)
            facing[sel] += wj[sel] * np.maximum(cs, 0.0)
    out[:, 1] = y
    if clamp_y is not None and np.any(y > clamp_y):
        # above clamp_y (the straps, the upper back) the wrap keeps the cut at clamp_y, which
        # the shoulders and shoulder blades outgrow (measured: the dress's back straps started
        # up to 5 cm inside the shoulders). Each 1 cm row there moves out (+-z) as a whole until
        # its points stand CLEARANCE clear of the whole body's surface, the moves eased in over
        # the rows below at RISE_SLOPE (measured on the dress: eased at 0.3, 46 % strain at the
        # side seams under the arms; at 0.075, 31 %)
        up = y > clamp_y
        zs = sections.surface_z(out[up, 0], y[up], sign)
        gap = np.where(np.isfinite(zs), sign * (zs - out[up, 2]) + CLEARANCE, -np.inf)  # > 0: must move out
        r_up = np.clip(np.round(f[up]).astype(int), 0, len(rows) - 1)
        move = np.zeros(len(rows))
        np.maximum.at(move, r_up, gap)
        move = _limit_slope(move, RISE_SLOPE * ROW)
        if lean:
            # ... and rows further off than that lean in (_lean_in), each point lowered so that
            # its vertical line keeps its length
            rows_lean = _lean_in(move[r_up] - gap, facing[up], r_up, top_y + rows * ROW > clamp_y)
            step = facing[:, None] * np.diff(rows_lean)[None, :]
            drop = np.concatenate([np.zeros((len(uv), 1)), np.cumsum(
                ROW - np.sqrt(np.maximum(ROW * ROW - step * step, 0.0)), axis=1)], axis=1)
            k = np.arange(len(uv))
            out[:, 1] -= (1.0 - w) * drop[k, j0] + w * drop[k, j0 + 1]
            out[:, 2] -= sign * facing * ((1.0 - w) * rows_lean[j0] + w * rows_lean[j0 + 1])
        out[:, 2] += sign * ((1.0 - w) * move[j0] + w * move[j0 + 1])
    return out


LEAN_SLOPE = 0.65  # see _lean_in


def _lean_in(room: np.ndarray, facing: np.ndarray, row: np.ndarray, above: np.ndarray):
    """How far the rows above clamp_y lean in toward the body: a point moves in (-+z) by
    facing x its row's lean, so the sides of the wrap stay; a row leans until one of its points
    stands CLEARANCE off the body (room: how far each point may move in, +inf where no body is
    under it, then as the row below), by at most LEAN_SLOPE per metre of panel height more
    than the row below. Returns the rows' leans (R,).
    Why: standing straight up from the bust, the straps of a sleeveless top started 31-34 cm
    apart across the shoulders (the default bodies' dress and sleeveless shirt in M); the seam
    pull swung them about their base, down below the shoulders, and default:female's dress
    slid off sideways at 3 of 8 cloth resolutions from 1.1 to 1.8 cm. Leaning, they start
    19 cm apart and every resolution sews, in 28-36 % fewer iterations. A steeper lean leaves
    diagonal springs at the neckline stretched (measured, placed dress and sleeveless shirt on
    both bodies, structural springs' p99: 13.6-17.5 % at 0.8 per metre; 10.5-14.8 % at 0.65;
    6.8-13.2 % before)."""
    limit = np.full(len(above), np.inf)
    np.minimum.at(limit, row, room / np.maximum(facing, 0.05))
    limit[~above] = 0.0
    last = 0.0
    for j in range(len(limit)):  # a row with no body under it (a strap above the shoulder) leans as the one below
        if np.isfinite(limit[j]):
            last = limit[j]
        else:
            limit[j] = last
    lean = -_limit_slope(-np.maximum(limit, 0.0), LEAN_SLOPE * ROW)  # the largest lean within limit and slope
    return lean


def _limit_slope(a: np.ndarray, step: float) -> np.ndarray:
    """a (rows, ...) raised, never lowered, until neighbouring rows differ by at most step."""
    a = a.copy()
    for j in range(len(a) - 2, -1, -1):  # downward from the top ...
        a[j] = np.maximum(a[j], a[j + 1] - step)
    for j in range(1, len(a)):  # ... and upward from the bottom
        a[j] = np.maximum(a[j], a[j - 1] - step)
    return a


def _groups(keys: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """(key, indices of the points with that key, in the points' order) for each distinct key,
    ascending: one stable sort instead of a mask over all points per key."""
    order = np.argsort(keys, kind="stable")
    uniq, starts = np.unique(keys[order], return_index=True)
    return [(k, order[lo:hi]) for k, lo, hi in zip(uniq, starts, [*starts[1:], len(order)])]


def _widths_at(outline: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Widths of a closed outline (M, 2) along the horizontal lines at heights v (K,): (K,)."""
    a, b = outline, np.roll(outline, -1, axis=0)
    vv = v[:, None]
    cross = (a[None, :, 1] - vv) * (b[None, :, 1] - vv) <= 0  # (K, M): edges each line meets
    rise = np.where(b[:, 1] != a[:, 1], b[:, 1] - a[:, 1], 1.0)
    t = np.clip((vv - a[None, :, 1]) / rise[None, :], 0, 1)
    xs = a[None, :, 0] + t * (b[None, :, 0] - a[None, :, 0])
    hit = cross.any(axis=1)
    wide = np.where(cross, xs, -np.inf).max(axis=1) - np.where(cross, xs, np.inf).min(axis=1)
    return np.where(hit, wide, np.ptp(outline[:, 0]))


def arm_path(points: np.ndarray, step: float = 0.005, smooth: float = 0.06) -> np.ndarray:
    """(K, 3) arm axis polyline (cap start, elbow, wrist) -> (M, 3) points every `step` metres,
    smoothed over `smooth` metres so that a sleeve wrapped around it has no crease at the elbow.
    The path is extended 15 cm beyond both ends (straight) so every sleeve point finds its ring."""
    p = np.asarray(points, dtype=np.float64)
    # repeated points (an arm centre line that ends on the wrist it was extended to) have no
    # direction: drop them (measured: NaN arc lengths, "arange: cannot compute length")
    keep = np.concatenate([[True], np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-6])
    p = p[keep]
    if len(p) < 2 or not np.isfinite(p).all():
        raise InputError("could not find the arm's axis to place the sleeve: the arms may touch "
                         "the body; a scan in an A-pose (arms about 45 degrees from the body) works")
    d0 = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
    d1 = (p[-1] - p[-2]) / np.linalg.norm(p[-1] - p[-2])
    ext = np.concatenate([[p[0] - 0.15 * d0], p, [p[-1] + 0.15 * d1]])
    seg = np.linalg.norm(np.diff(ext, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.arange(0.0, s[-1], step)
    dense = np.stack([np.interp(t, s, ext[:, c]) for c in range(3)], axis=1)
    k = max(1, int(round(smooth / step / 2)))
    pad = np.concatenate([np.repeat(dense[:1], k, 0), dense, np.repeat(dense[-1:], k, 0)])
    kern = np.ones(2 * k + 1) / (2 * k + 1)
    sm = np.stack([np.convolve(pad[:, c], kern, mode="valid") for c in range(3)], axis=1)
    # keep the original start (the cap top is placed relative to it)
    return sm - sm[int(round(0.15 / step))] + p[0]


def _arm_frames(path: np.ndarray, origin: int):
    """Arc length (0 at path[origin]), unit tangents, 'up' and 'front' vectors per path point."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    s -= s[origin]
    tan = np.gradient(path, axis=0)
    tan /= np.linalg.norm(tan, axis=1, keepdims=True)
    up = np.array([0.0, 1.0, 0.0])[None] - tan[:, 1:2] * tan
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    fwd = np.cross(tan, up)
    fwd *= np.where(fwd[:, 2:3] < 0, -1.0, 1.0)  # u > 0 toward the front (+z) for both arms
    return s, tan, up, fwd


def arm_centre_line(arm_vertices: np.ndarray, joints: np.ndarray, band: float = 0.03) -> np.ndarray:
    """(K, 3) centres of the arm's surface in bands across the joint path (upper arm joint,
    elbow, wrist) from 6 cm below the upper arm joint to the wrist: the joints of a rig sit
    off the middle of the arm (the shoulder joint inside the deltoid). The last point is level
    with the wrist joint on the line of the last bands."""
    from scipy.spatial import cKDTree

    path = arm_path(joints)
    origin = int(round(0.15 / 0.005))
    s, _, _, _ = _arm_frames(path, origin)
    s_wrist = float(s[int(np.argmin(np.linalg.norm(path - joints[-1], axis=1)))])
    _, i = cKDTree(path).query(arm_vertices)
    sv = s[i]
    out = []
    for b0 in np.arange(0.06, s_wrist - band / 2, band):
        sel = (sv >= b0) & (sv < b0 + band)
        if sel.sum() >= 8:
            out.append(arm_vertices[sel].mean(axis=0))
    if len(out) >= 3:
        # the line ends level with the wrist joint, straight on from the forearm's last bands:
        # the joint itself sits off the forearm's middle, and a path bent to reach it turned
        # tighter than a sleeve's radius there (measured: the cuff placed 185 % stretched)
        d = out[-1] - out[-3]
        d /= np.linalg.norm(d)
        out.append(out[-1] + max(float(np.dot(joints[-1] - out[-1], d)), 0.0) * d)
    else:
        out.append(joints[-1])
    return np.array(out)


def arm_radius_profile(arm_vertices: np.ndarray, path: np.ndarray, origin: int,
                       s_query: np.ndarray, s_end: float) -> np.ndarray:
    """90th percentile distance of the arm's vertices from the path in 2 cm bands of arc
    length (0 at path[origin]), hand (beyond s_end) excluded, at arc lengths s_query."""
    from scipy.spatial import cKDTree

    s, _, _, _ = _arm_frames(path, origin)
    d, i = cKDTree(path).query(arm_vertices)
    keep = s[i] <= s_end - 0.03  # the wrist bands run into the palm
    d, band = d[keep], np.round(s[i][keep] / 0.02).astype(int)
    keys = np.unique(band)
    rmax = np.array([np.percentile(d[band == k], 90) for k in keys])
    return np.interp(s_query, keys * 0.02, rmax)


def wrap_sleeve(uv: np.ndarray, path: np.ndarray, origin: int, radius: np.ndarray) -> np.ndarray:
    """A sleeve on a bent arm: (n, 2) sleeve points (v = 0 at the cap top, negative toward the
    cuff; u around the arm, u = 0 on top, u > 0 toward the front) -> (n, 3) on tubes around the
    smoothed axis `path` (from arm_path), whose point `origin` is at v = 0; radius: (n,) the tube
    radius at each point (m). The underarm seam (u = +-half the width) lies under the arm."""
    s, tan, up, fwd = _arm_frames(path, origin)
    along = np.clip(-uv[:, 1], s[0], s[-1])
    idx = np.clip(np.searchsorted(s, along) - 1, 0, len(s) - 2)
    w = ((along - s[idx]) / np.maximum(s[idx + 1] - s[idx], 1e-12))[:, None]
    centre = (1 - w) * path[idx] + w * path[idx + 1]
    u_ = (1 - w) * up[idx] + w * up[idx + 1]
    f_ = (1 - w) * fwd[idx] + w * fwd[idx + 1]
    theta = (uv[:, 0] / radius)[:, None]
    return centre + radius[:, None] * (np.cos(theta) * u_ + np.sin(theta) * f_)


# ------------------------------------------------------------------ trousers


FOOT_TOP, FOOT_TAPER = 0.10, 0.15  # m: below FOOT_TOP the trouser leg is one tube around the foot


class LegSections:
    """Per-leg ellipses (centre x, z; semi-axes a, b) every 1 cm: below the crotch the cut of
    each leg, above it the body's half (x > 0 for the left leg, x < 0 for the right) of the
    torso cut, so a trouser leg's tube continues smoothly into the seat. lowest: the height (m)
    of the garment's hem -- the foot's tube covers the foot from there up, not the toes below."""

    def __init__(self, body: Body, lowest: float = 0.0):
        v, f = body.vertices, body.faces
        if body.segments is not None:
            keep_seg = np.isin(body.segments, [SEGMENTS.index(s) for s in ("torso", "left_leg", "right_leg")])
            f = f[keep_seg[f].all(axis=1)]
        self.ys = np.arange(0.02, float(v[:, 1].max()) * 0.7, 0.01)
        cuts = slice_stack(v, f, self.ys)
        ell = {1: np.full((len(self.ys), 5), np.nan), -1: np.full((len(self.ys), 5), np.nan)}
        foot = {1: [], -1: []}
        for k, pieces in enumerate(cuts):
            central = [p for p in pieces if p.xmin < 0.0 < p.xmax]
            for s in (1, -1):
                if central:
                    c = max(central, key=lambda p: p.length).points
                    pts = c[s * c[:, 0] >= 0]
                    if len(pts) < 3:
                        continue
                    pts = np.concatenate([pts, [[0.0, pts[:, 1].min()], [0.0, pts[:, 1].max()]]])
                else:
                    side = [p for p in pieces if s * p.centroid[0] > 0]
                    if not side:
                        continue
                    pts = max(side, key=lambda p: p.length).points
                ell[s][k] = _covering_ellipse(pts)
                if lowest - 0.01 <= self.ys[k] <= FOOT_TOP:
                    foot[s].append(pts)
        for s in (1, -1):
            ok = np.isfinite(ell[s][:, 0])
            if ok.sum() < 10:
                raise InputError("could not find the body's legs to place the trousers")
            for c in range(5):
                ell[s][:, c] = np.interp(self.ys, self.ys[ok], ell[s][ok, c])
            if foot[s]:
                # the foot grows fast toward the sole: below the ankle one tube around the whole
                # foot, tapering into the leg's own cuts over FOOT_TAPER (no rows torn apart)
                fe = np.array(_covering_ellipse(np.concatenate(foot[s])))
                w = np.clip((self.ys - FOOT_TOP) / FOOT_TAPER, 0.0, 1.0)[:, None]
                ell[s] = w * ell[s] + (1 - w) * fe[None]
        self.ell = ell

    def at(self, y: np.ndarray, s: int) -> np.ndarray:
        """(len(y), 5) ellipses of leg s at heights y, + how much covering grew them."""
        return np.stack([np.interp(y, self.ys, self.ell[s][:, c]) for c in range(5)], axis=1)


def wrap_trousers(uv: np.ndarray, side: str, leg: int, top_y: float, crotch_y: float, crease: float,
                  torso: BodySections, legs: LegSections, half_girth, leg_girth,
                  blend: float = 0.10) -> np.ndarray:
    """(n, 2) trouser panel points (metres; v = 0 at the waist, u -> world x, u = 0 on the
    centre front/back line) -> (n, 3). side: 'front'/'back'; leg: +1 body's left (x > 0), -1
    right; crotch_y: height of the garment's crotch point; crease: u of the leg's crease line.
    half_girth(v) / leg_girth(v): the garment's girth over front + back (one side of the body /
    one leg) at panel height v, to widen the ellipses where the garment is looser.

    Above crotch_y + blend the panel wraps the torso's ellipse by arc length from the centre
    line (the crotch extension, past the centre, is folded onto it and stands off a little);
    below crotch_y it wraps its own leg's ellipse by arc length from the crease line (above
    crotch_y that of the crotch); in between the two are blended at the panel's own heights
    (squeezing the rows toward the crotch, as before, started the springs there 58 % short and
    74 % long)."""
    u, v = uv[:, 0], uv[:, 1]
    y = top_y + v
    sg = 1.0 if side == "front" else -1.0
    rows = np.round(v / 0.01).astype(int)
    p_t = np.zeros((len(uv), 3))
    p_l = np.zeros((len(uv), 3))
    groups = _groups(rows)
    uniq = np.array([r for r, _ in groups])
    vr = uniq * 0.01
    yr = top_y + vr
    # the torso's and the leg's ellipse of each row
    # (a garment tighter than the covering ellipse shrinks it -- at most back to the cut's box
    # ellipse -- so its seams start closed: a waist whose side seams start open slides down)
    t_cut, l_cut = torso.at(np.maximum(yr, crotch_y), grown=True), legs.at(np.minimum(yr, crotch_y), leg)
    t_ell, l_ell = np.zeros((len(uniq), 4)), np.zeros((len(uniq), 4))
    for i in range(len(uniq)):
        cx, cz, a, b, kc = t_cut[i]
        a, b = a + CLEARANCE, b + CLEARANCE
        k = max(1.0 / kc, half_girth(vr[i]) / _half_perimeter(a, b))
        t_ell[i] = cx, cz, a * k, b * k
        cx, cz, a, b, kc = l_cut[i]
        a, b = a + CLEARANCE, b + CLEARANCE
        k = max(1.0 / kc, leg_girth(min(vr[i], crotch_y - top_y)) / (2 * _half_perimeter(a, b)))
        l_ell[i] = cx, cz, a * k, b * k
    t_arcs, l_arcs = _ellipse_arcs(t_ell[:, 2], t_ell[:, 3]), _ellipse_arcs(l_ell[:, 2], l_ell[:, 3])
    for i, (_, sel) in enumerate(groups):
        # torso
        cx, cz, a, b = t_ell[i]
        t = leg * u[sel]  # toward the outseam; < 0 in the crotch extension
        sn, cs = _ellipse_point(a, b, leg * np.maximum(t, 0.0), t_arcs[i])
        stand = 0.5 * np.maximum(-t, 0.0)
        p_t[sel, 0] = cx + (a + stand) * sn
        p_t[sel, 1] = y[sel]
        p_t[sel, 2] = cz + sg * (b + stand) * cs
        # leg
        cx, cz, a, b = l_ell[i]
        sn, cs = _ellipse_point(a, b, u[sel] - crease, l_arcs[i])
        p_l[sel, 0] = cx + a * sn
        p_l[sel, 1] = y[sel]
        p_l[sel, 2] = cz + sg * b * cs
    # the torso's share: 0 at the crotch, 1 above the blend; as g^0.9, not linearly, which left
    # the seat of default:female and the front crotch of default:male 0.1 mm inside the body
    g = np.clip((y - crotch_y) / blend, 0.0, 1.0)[:, None] ** 0.9
    return g * p_t + (1 - g) * p_l


# ------------------------------------------------------------------ a pattern's own placement, on another body

# The heights a GarmentCode specification's own placement assumes: GarmentCode's mean female body
# (../shared/samples/garmentcode/mean_female.obj, the body of its sample patterns), measured by
# engine.body.measure. A pattern placed for it is carried onto another body landmark by landmark.
GARMENTCODE_LANDMARKS = (("knee_height", 0.410), ("crotch_height", 0.758), ("hip_height", 0.805),
                         ("waist_height", 1.080), ("bust_height", 1.185), ("shoulder_height", 1.370),
                         ("height", 1.662))
# ... and its girths (bust, waist, hips, m), measured the same way
GARMENTCODE_GIRTHS = (("bust", 0.975), ("waist", 0.798), ("hips", 1.049))
SAME_BODY = 0.01  # m: landmarks all this close to the reference's: the body the pattern was made for
# The same body's arms (engine.body.fit.fit_rig on the sample scan, engine.pattern.catalogue's arm
# joints): side -> (shoulder, elbow) joint, world metres. They hang 50 degrees from the vertical;
# the default bodies' 42-43, 2.7 cm (female) nearer the middle
GARMENTCODE_ARMS = {"left": ((0.188, 1.312, -0.004), (0.402, 1.131, 0.040)),
                    "right": ((-0.181, 1.312, -0.004), (-0.395, 1.131, 0.038))}
SLEEVE_BEYOND = 0.05  # m: a panel whose centre lies this far out past the shoulder joint, above
SLEEVE_BELOW = 0.15  # m: ... the joint's height less this, is a sleeve (wrapped round the arm)


def sleeve_side(outline: np.ndarray) -> str | None:
    """'left' / 'right' if a panel GarmentCode placed round its mean body (its placed outline
    (M, 3)) lies over that arm of it (SLEEVE_BEYOND, SLEEVE_BELOW), else None."""
    c = outline.mean(axis=0)
    for side, (s_ref, _) in GARMENTCODE_ARMS.items():
        if c[0] * s_ref[0] > 0 and abs(c[0]) > abs(s_ref[0]) + SLEEVE_BEYOND and c[1] > s_ref[1] - SLEEVE_BELOW:
            return side
    return None


def sleeve_tube(joints: np.ndarray, side: str, p: np.ndarray, o: np.ndarray) -> np.ndarray:
    """A sleeve panel GarmentCode laid flat beside its mean body's arm `side` (points p (n, 3)
    and its outline o (M, 3), as placed) -> (n, 3) round the target's arm (joints (3, 3):
    shoulder, elbow, wrist), as the catalogue's sleeves are (wrap_sleeve): in the reference
    arm's frame a point's distance along the arm from the panel's innermost point (the cap)
    becomes its distance from the target's shoulder joint, and its distance below the panel's
    top line (the seam over the arm) the way round a tube -- by the front for a panel in front
    of the arm, by the back for one behind it -- whose half circumference is the panel's width
    (at least the arm's radius and CLEARANCE)."""
    s_ref, e_ref = (np.array(q) for q in GARMENTCODE_ARMS[side])
    d = (e_ref - s_ref) / np.linalg.norm(e_ref - s_ref)
    up = np.array([0.0, 1.0, 0.0]) - d[1] * d
    up /= np.linalg.norm(up)
    fwd = np.cross(d, up)
    fwd *= 1.0 if fwd[2] >= 0 else -1.0

    def frame(q):
        r = q - s_ref
        return r @ d, r @ up, r @ fwd

    a_o, c_o, f_o = frame(o)
    a_p, c_p, _ = frame(p)
    top = c_o.max()
    radius = max((top - c_o.min()) / np.pi, 0.045 + CLEARANCE)
    way = 1.0 if f_o.mean() > 0 else -1.0
    uv = np.stack([way * (top - c_p), a_o.min() - a_p], axis=1)
    return wrap_sleeve(uv, arm_path(joints), int(round(0.15 / 0.005)), np.full(len(p), radius))


def pattern_placement(spec, body: Body, inside=None):
    """A pattern file's placement on `body`: its own translation and rotation (GarmentCode's,
    engine.garment.garment.spec_placement) on the body it was made for; on another body the
    placed panels are carried there from GarmentCode's mean body by the landmarks -- every
    height mapped piecewise linearly through floor, knee, crotch, hip, waist, bust, shoulder and
    crown. Then, as the catalogue's garments are placed:
    - a sleeve (a panel laid out over one of the mean body's arms) is wrapped round the body's
      arm (sleeve_tube);
    - a panel reaching above the armpits (a top's, a dress's) is wrapped round the torso from
      its carried top down by its own length (wrap_torso);
    - the others (skirts, trousers) keep the carried heights and, where the body is wider than
      the panels allow, are pushed out round its cross-section (torso and legs) to CLEARANCE.
    Measured on GarmentCode's own T-shirt (flat front and back panels 45 cm apart, half sleeves
    laid beside the arms), carried by heights alone: it fell from the shoulders of default:female
    and default:male before its 5 cm shoulder seams closed; wrapped, it sews on both.
    inside: points (N, 3) -> (N,) bool, inside the body (the scene's; None: a pattern's own layout
    is kept on its own body only). Returns (placement, a note or None)."""
    from engine.body.measure import measure
    from engine.garment.garment import spec_placement
    from engine.pattern import geometry as geo

    own = spec_placement(spec, body.to_world)
    try:
        m = measure(body)
    except TryonError:
        return own, "the body could not be measured: the pattern keeps its own placement"
    floor = float(body.vertices[:, 1].min())  # the measurements are heights above it
    ref, tgt = [0.0], [floor]
    for name, y in GARMENTCODE_LANDMARKS:
        t = floor + float(getattr(m, name))
        if np.isfinite(t) and t > tgt[-1] + 0.02:
            ref.append(y)
            tgt.append(t)
    if len(ref) == len(GARMENTCODE_LANDMARKS) + 1 and np.abs(np.subtract(ref, tgt)).max() < SAME_BODY:
        return own, None
    rel = spec.properties.curvature_coords == "relative"
    girths = np.array([float(getattr(m, k)) - g for k, g in GARMENTCODE_GIRTHS])
    if (len(ref) == len(GARMENTCODE_LANDMARKS) + 1 and np.abs(np.subtract(ref, tgt)).max() < LIKE_BODY
            and np.all(np.abs(girths) < LIKE_GIRTH) and inside is not None
            and _clears(spec, own, inside, rel, floor + float(m.shoulder_height))):
        return own, OWN_CLEARS
    ref_a, tgt_a = np.array(ref), np.array(tgt)
    sections = BodySections(body)

    def heights(p):
        # heights: piecewise linear through the landmarks, extended past the last by its slope
        y = p[:, 1]
        hi = y > ref_a[-1]
        y_new = np.interp(y, ref_a, tgt_a)
        y_new[hi] = tgt_a[-1] + (y[hi] - ref_a[-1]) * (tgt_a[-1] - tgt_a[-2]) / (ref_a[-1] - ref_a[-2])
        p[:, 1] = y_new
        return p

    outlines = {n: own(n, pn, geo.outline(pn, spec.scale, rel)) for n, pn in spec.pattern.panels.items()}
    sleeves = {n: s for n, s in ((n, sleeve_side(o)) for n, o in outlines.items()) if s is not None}
    arms = _arms_of(body, m) if sleeves else None
    armpit = floor + float(m.armpit_height)

    def place(name, panel, uv):
        p = own(name, panel, uv)
        o = outlines[name]
        if name in sleeves and arms is not None:
            return sleeve_tube(arms[sleeves[name]], sleeves[name], p, o)
        top_own = float(o[:, 1].max())
        top = float(heights(np.array([[0.0, top_own, 0.0]]))[0, 1])
        if name not in sleeves and np.isfinite(armpit) and top > armpit:
            # a top's panel, laid flat in front of or behind the body: wrapped round it as the
            # catalogue's are (wrap_torso), its x the way round from the front (back) centre
            # line, its top at the carried height and its own length below it (carried heights
            # stretch a panel between landmarks further apart: on default:male GarmentCode's
            # T-shirt sprang up to the chest)
            uv_o = np.stack([o[:, 0], o[:, 1] - top_own], axis=1)
            both = np.concatenate([uv_o, uv_o[::-1] * np.array([-1.0, 1.0])])  # widths both sides of x = 0
            hint = PanelHint(side="front" if o[:, 2].mean() > 0 else "back")
            return wrap_torso(np.stack([p[:, 0], p[:, 1] - top_own], axis=1), hint, sections, top, both,
                              clamp_y=armpit, lean=not sleeves)
        p = heights(p)
        y_new = p[:, 1]
        # out of the body: onto the cross-section's ellipse grown by CLEARANCE where inside it
        inside_rows = (y_new >= sections.ys[0]) & (y_new <= sections.ys[-1])
        cx, cz, a, b = sections.at(y_new).T
        dx, dz = p[:, 0] - cx, p[:, 2] - cz
        r = np.sqrt((dx / (a + CLEARANCE)) ** 2 + (dz / (b + CLEARANCE)) ** 2)
        push = inside_rows & np.isfinite(r) & (r < 1.0) & (r > 1e-9)
        p[push, 0] = cx[push] + dx[push] / r[push]
        p[push, 2] = cz[push] + dz[push] / r[push]
        return p

    return place, CARRIED


SEAM_LIFT_MAX = 0.10  # m: a garment is raised at most this far so that its seams close over the body ...
SEAM_LIFT_STEP = 0.005  # ... found in these steps ...
SEAM_LIFT_MARGIN = 0.01  # ... and raised this much further


def seam_lift(positions: np.ndarray, seams: np.ndarray, inside, above: float) -> float:
    """How far (m) to raise a placed garment so that every seam above height `above` (the
    armpits) can close over the body: the straight path between each stitch's two sides,
    which the sewing pulls them along, clear of the body (`inside`: points (N, 3) -> (N,) bool)
    -- 0 when it is already, or when more than SEAM_LIFT_MAX would be needed (a seam round the
    body, not over it). GarmentCode places a top's shoulder seams at its body's shoulder height,
    a few cm under the surface of the shoulders beside the neck: pulled shut through the
    shoulder, narrow straps slid off it and the top fell (raised 4 cm, such a top drapes)."""
    a, b = positions[seams[:, 0]], positions[seams[:, 1]]
    t = np.linspace(0.0, 1.0, 9)
    path = a[:, None, :] * (1.0 - t)[None, :, None] + b[:, None, :] * t[None, :, None]  # (P, 9, 3)
    path = path[path[:, :, 1].min(axis=1) > above].reshape(-1, 3)
    if not len(path):
        return 0.0
    for dy in np.arange(0.0, SEAM_LIFT_MAX + 1e-9, SEAM_LIFT_STEP):
        if not np.any(inside(path + np.array([0.0, dy, 0.0]))):
            return 0.0 if dy == 0.0 else float(dy + SEAM_LIFT_MARGIN)
    return 0.0


def _clears(spec, own, inside, rel: bool, head_y: float = np.inf) -> bool:
    """Whether the pattern's own layout lies round this body as GarmentCode lays it round the body
    it was made for: no more than CLEAR_INSIDE of its panels' points (outlines and a grid, 2 cm or coarser,
    inside them) inside the body (`inside`). GarmentCode can make a pattern for any body (its
    sampler's --body), and a layout that clears a body of like landmarks was made for one like it.
    Panels laid out round the head (half their points above head_y, the shoulders: a hood) are not
    counted: GarmentCode lays a hood's halves through the head, on the body it made them for too
    (mean_female 113_004's on mean_female: 29-30 % of their points inside it; f_smpl 127_008's and
    127_010's on f_smpl: 43-47 %), and sewing pulls them out round it."""
    from matplotlib.path import Path as MplPath

    from engine.pattern import geometry as geo

    pts = []
    for n, pn in spec.pattern.panels.items():
        o = geo.outline(pn, spec.scale, rel)
        lo, hi = o.min(axis=0), o.max(axis=0)
        step = max(0.02, float(np.sqrt(np.prod(hi - lo) / 20_000)))  # (at most ~20,000 points a panel)
        gx, gy = np.meshgrid(np.arange(lo[0], hi[0], step), np.arange(lo[1], hi[1], step))
        grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
        grid = grid[MplPath(o).contains_points(grid)] if len(grid) else grid
        p = own(n, pn, np.concatenate([o, grid]))
        if np.median(p[:, 1]) <= head_y:
            pts.append(p)
    if not pts:
        return True
    pts = np.concatenate(pts)
    return bool(np.all(np.isfinite(pts))) and float(np.mean(inside(pts))) <= CLEAR_INSIDE


LIKE_BODY = 0.06  # m: landmarks all this close to the mean body's ...
LIKE_GIRTH = 0.05  # m: ... and bust, waist and hips this close: a body like it
CLEAR_INSIDE = 0.005  # share of a layout's points inside the body it still clears
OWN_CLEARS = ("the pattern's own placement: its layout clears this body, whose landmarks and girths are "
              "like GarmentCode's mean body's")
CARRIED = ("placed from the body's landmarks and arms (the pattern's own placement is for GarmentCode's "
           "mean body)")
# what a try-on whose placement was CARRIED adds to a sewing failure (engine.scene.tryon)
CARRIED_HINT = ("This pattern was laid out round GarmentCode's mean body and carried onto this body by its "
                "landmarks, which does not always leave seams that can close: dress the body the pattern was "
                "made for, or make the pattern in GarmentCode for this body's measurements")


def _arms_of(body: Body, m) -> dict[str, np.ndarray] | None:
    """The body's arm joints (engine.pattern.catalogue.arm_joints): from its rig, or from the
    default skeleton fitted to it (a scan; the chart of its measurements `m` picks which);
    None when neither can be had."""
    arms = arm_joints(body)
    if arms is None:
        from engine.body.fit import fit_rig

        try:
            arms = arm_joints(fit_rig(body, "male" if chart_of(body, m) == "men" else "female"))
        except TryonError:
            return None
    return arms
