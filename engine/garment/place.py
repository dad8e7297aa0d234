"""Place flat panels around a body from its landmarks (catalogue garments, and patterns on a
body they were not made for).

Torso and hip panels are wrapped onto an elliptic cylinder around the body: at every height the
ellipse is the body's cross-section (torso and legs, never the arms) grown by a clearance and,
where the garment is wider than that, grown until the panel's width spans half of it. A panel's
horizontal coordinate is laid out as arc length from the front (or back) centre line, so front and
back panels meet at the sides and the side seams start almost closed. Sleeves are wrapped onto a
circular cylinder around the arm's axis with their underarm seam underneath.
"""

from __future__ import annotations

import numpy as np

from engine.body.measure import slice_stack
from engine.body.types import SEGMENTS, Body
from engine.errors import InputError
from engine.pattern.spec import Panel, PanelHint

CLEARANCE = 0.02  # m between the body and a freshly placed panel


class BodySections:
    """Ellipses (centre x, z; semi-axes a, b) of the body without its arms, every 1 cm."""

    def __init__(self, body: Body):
        v, f = body.vertices, body.faces
        if body.segments is not None:
            keep_seg = np.isin(body.segments, [SEGMENTS.index(s) for s in ("torso", "left_leg", "right_leg")])
            f = f[keep_seg[f].all(axis=1)]
        self.ys = np.arange(0.02, float(v[:, 1].max()), 0.01)
        cuts = slice_stack(v, f, self.ys)
        ell = np.full((len(self.ys), 4), np.nan)
        for k, pieces in enumerate(cuts):
            # scans: arms and hands hang beside the hips; keep pieces near the body axis
            pts = [p.points for p in pieces if abs(p.centroid[0]) < 0.2 or body.segments is not None]
            if not pts:
                continue
            p = np.concatenate(pts)
            lo, hi = p.min(axis=0), p.max(axis=0)
            ell[k] = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2]
        ok = np.isfinite(ell[:, 0])
        if ok.sum() < 10:
            raise InputError("could not find the body's cross-sections to place the garment")
        for c in range(4):  # fill gaps (e.g. a hole in a scan) by interpolation
            ell[:, c] = np.interp(self.ys, self.ys[ok], ell[ok, c])
        self.ell = ell

    def at(self, y: np.ndarray) -> np.ndarray:
        """(len(y), 4) ellipses at heights y."""
        return np.stack([np.interp(y, self.ys, self.ell[:, c]) for c in range(4)], axis=1)


def _ellipse_point(a: float, b: float, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Angles theta (from +z toward +x) at arc lengths s from theta = 0 on the ellipse
    (a along x, b along z); returns (sin, cos)."""
    th = np.linspace(-np.pi, np.pi, 721)
    pts = np.stack([a * np.sin(th), b * np.cos(th)], axis=1)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    arc -= np.interp(0.0, th, arc)
    t = np.interp(s, arc, th)
    return np.sin(t), np.cos(t)


def _half_perimeter(a: float, b: float) -> float:
    h = ((a - b) / (a + b)) ** 2
    return 0.5 * np.pi * (a + b) * (1 + 3 * h / (10 + np.sqrt(4 - 3 * h)))  # Ramanujan


def wrap_torso(uv: np.ndarray, hint: PanelHint, sections: BodySections, top_y: float,
               outline: np.ndarray, widen_to: float | None = None, clamp_y: float | None = None) -> np.ndarray:
    """(n, 2) panel points (metres; v = 0 at the panel's top, u = 0 on its centre line) ->
    (n, 3) world points on the front (hint.side == 'front') or back of the body.
    outline: (M, 2) the panel's outline, for its width at each height; clamp_y: above this
    height use the cross-section at it (a top's shoulder straps go over the shoulders, not
    around the neck)."""
    u, v = uv[:, 0], uv[:, 1]
    y = top_y + v
    sign = 1.0 if hint.side == "front" else -1.0
    out = np.zeros((len(uv), 3))
    # the panel's width at each height (from its outline), in 1 cm bands
    rows = np.round(v / 0.01).astype(int)
    for r in np.unique(rows):
        sel = rows == r
        yr = top_y + r * 0.01
        if clamp_y is not None:
            yr = min(yr, clamp_y)
        cx, cz, a, b = sections.at(np.array([yr]))[0]
        a, b = a + CLEARANCE, b + CLEARANCE
        width = _width_at(outline, r * 0.01)
        half = _half_perimeter(a, b)
        k = max(1.0, width / half) if widen_to is None else max(1.0, widen_to / half)
        a, b = a * k, b * k
        sn, cs = _ellipse_point(a, b, u[sel])
        out[sel, 0] = cx + a * sn
        out[sel, 1] = y[sel]
        out[sel, 2] = cz + sign * b * cs
    return out


def _width_at(outline: np.ndarray, v: float) -> float:
    """Width of a closed outline (M, 2) along the horizontal line at height v."""
    a, b = outline, np.roll(outline, -1, axis=0)
    cross = (a[:, 1] - v) * (b[:, 1] - v) <= 0
    if not cross.any():
        return float(np.ptp(outline[:, 0]))
    t = np.clip((v - a[cross, 1]) / np.where(b[cross, 1] != a[cross, 1], b[cross, 1] - a[cross, 1], 1.0), 0, 1)
    xs = a[cross, 0] + t * (b[cross, 0] - a[cross, 0])
    return float(xs.max() - xs.min())


def wrap_arm(uv: np.ndarray, shoulder: np.ndarray, wrist: np.ndarray, radius: float, side: str) -> np.ndarray:
    """(n, 2) sleeve points (v = 0 at the cap top, negative toward the cuff; u around the arm,
    u = 0 on top of the arm) -> (n, 3) on a cylinder of `radius` around shoulder->wrist, the
    underarm seam (u = +-half circumference) under the arm."""
    axis = wrist - shoulder
    length = np.linalg.norm(axis)
    if length < 0.1:
        raise InputError("could not find the arm's axis to place a sleeve")
    ax = axis / length
    # 'up' around the arm: world up made perpendicular to the arm axis
    up = np.array([0.0, 1.0, 0.0]) - ax[1] * ax
    up /= np.linalg.norm(up)
    fwd = np.cross(ax, up) if side == "left" else np.cross(up, ax)
    if fwd[2] < 0:
        fwd = -fwd
    theta = uv[:, 0] / radius
    # u > 0 goes toward the front of the arm
    ring = np.cos(theta)[:, None] * up + np.sin(theta)[:, None] * fwd
    along = -uv[:, 1]  # v is negative toward the cuff
    return shoulder + along[:, None] * ax + radius * ring


def panel_outline_2d(panel: Panel, scale: float) -> np.ndarray:
    from engine.pattern import geometry as geo

    return geo.outline(panel, scale)
