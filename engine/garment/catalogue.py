"""The catalogue's garments cut for a body and placed round it: the pattern from
engine.pattern.catalogue (sized by the chart, lengths from the body's landmarks), each panel's
placement from engine.garment.place (wrapped round the torso, sleeves round the arms, trouser legs
round the legs)."""

from __future__ import annotations

import numpy as np

from engine.body.types import SEGMENTS, Body
from engine.errors import InputError
from engine.garment.place import (CLEARANCE, BodySections, LegSections, arm_centre_line, arm_path, arm_radius_profile,
                                  wrap_sleeve, wrap_torso, wrap_trousers)
from engine.pattern import geometry as geo
from engine.pattern.catalogue import AUTO, CATALOGUE, Made, SleevePlan, _fit, arm_joints, recommend_size

NEEDS_ARMS = {"shirt"}  # garments placed along the arms' joints (see make_garment)


def make_garment(name: str, body: Body, size: str = "M"):
    """(PatternSpec, placement function, display name) of a catalogue garment on this body."""
    if name not in CATALOGUE:
        raise InputError(f"unknown garment '{name}'; the catalogue has: {', '.join(CATALOGUE)}")
    chosen = size == AUTO
    if chosen:
        size = recommend_size(name, body)
    fit = _fit(body, size)
    arm_body = body
    if name in NEEDS_ARMS and fit.arms is None:
        # a scan has no skeleton: its arm axes and arm vertices come from the default skeleton
        # fitted to it (engine.body.fit, as for walking); the drape still collides with the
        # scan as loaded
        from engine.body.fit import fit_rig

        arm_body = fit_rig(body, "male" if fit.men else "female")
        fit.arms = arm_joints(arm_body)
    made = CATALOGUE[name][0](fit)
    # covering ellipses for every garment (the box's inscribed one started the male hips inside
    # the skirt and dress)
    sections = BodySections(body, cover=True)
    scale = made.spec.scale
    outlines = {n: geo.outline(p, scale) for n, p in made.spec.pattern.panels.items()}
    special = {n: _sleeve_placer(arm_body, plan, outlines[n]) for n, plan in made.sleeve_axes.items()}
    if made.legs:
        special.update(_trouser_placers(body, made, sections, outlines))

    def place(pname, panel, uv):
        if pname in special:
            return special[pname](uv)
        hint = made.hints[pname]
        return wrap_torso(uv, hint, sections, made.tops[pname] / 100.0, outlines[pname], clamp_y=made.clamp_y,
                          lean=not made.sleeve_axes)

    how = ", chosen from the body's girths" if chosen else ""
    return made.spec, place, f"{name} ({size}, {'men' if fit.men else 'women'}'s chart{how})"


def _row_widths(outline: np.ndarray, vs: np.ndarray, u_min: float = -np.inf) -> np.ndarray:
    """Width of a closed outline (M, 2) along horizontal lines at heights vs, counting only
    u >= u_min."""
    a, b = outline, np.roll(outline, -1, axis=0)
    out = np.zeros(len(vs))
    for k, v in enumerate(vs):
        cross = (a[:, 1] - v) * (b[:, 1] - v) <= 0
        if not cross.any():
            continue
        dy = np.where(b[cross, 1] != a[cross, 1], b[cross, 1] - a[cross, 1], 1.0)
        t = np.clip((v - a[cross, 1]) / dy, 0, 1)
        xs = a[cross, 0] + t * (b[cross, 0] - a[cross, 0])
        out[k] = max(0.0, xs.max() - max(xs.min(), u_min))
    return out


# m: a sleeve's axis is smoothed over this length. A tube of radius r around an axis that bends
# with radius R is stretched by r / R on the outside of the bend: over 6 cm the elbow bent the
# placed sleeve by up to 163 % (default:male); over 16 cm by 47 %, the sleeve still on the arm
SLEEVE_SMOOTH = 0.16


def _sleeve_placer(body: Body, plan: SleevePlan, outline: np.ndarray):
    """Placement of one sleeve: tubes around the arm's (smoothed, bent) axis, the cap top at the
    shoulder point, radius max(the sleeve's width / 2 pi, the arm's radius + clearance)."""
    j = plan.joints
    if body.segments is not None:
        arm_v = body.vertices[body.segments == SEGMENTS.index(f"{plan.side}_arm")]
    else:
        arm_v = None
    vs = np.arange(float(outline[:, 1].min()) - 0.01, 0.011, 0.01)
    widths = _row_widths(outline, vs)
    cap_v = float(vs[int(np.argmax(widths))])  # the widest row: the underarm line
    full = np.where(vs < cap_v, widths, widths.max())  # in the cap the tube is the underarm's

    step = 0.005
    origin = int(round(0.15 / step))
    centres = arm_centre_line(arm_v, j) if arm_v is not None and len(arm_v) > 50 else j[1:]
    d1 = centres[min(3, len(centres) - 2)] - centres[0]
    d1 /= np.linalg.norm(d1)
    up = np.array([0.0, 1.0, 0.0]) - d1[1] * d1
    up /= np.linalg.norm(up)
    path0 = arm_path(np.concatenate([[plan.cap_top], centres]), step, SLEEVE_SMOOTH)
    s0 = _arc_to(path0, origin, j[2])

    def radius_along(path, s, s_end):
        # in the cap the arm's cut runs into the deltoid and the torso: use the underarm's
        s = np.maximum(s, -cap_v)
        r_w = np.interp(-s, vs, full) / (2 * np.pi)
        if arm_v is None:
            return np.maximum(r_w, 0.045 + CLEARANCE)
        return np.maximum(r_w, arm_radius_profile(arm_v, path, origin, s, s_end) + CLEARANCE)

    # the tube's top line runs through the shoulder point: start the axis one radius below it
    r0 = float(radius_along(path0, np.array([0.0]), s0)[0])
    start = plan.cap_top - r0 * up
    path = arm_path(np.concatenate([[start], centres]), step, SLEEVE_SMOOTH)
    r_rows = radius_along(path, -vs, _arc_to(path, origin, j[2]))
    r_rows = np.convolve(np.pad(r_rows, 4, mode="edge"), np.ones(9) / 9, mode="valid")  # no bulges

    def place(uv):
        r = np.interp(uv[:, 1], vs, r_rows)
        return wrap_sleeve(uv, path, origin, r)

    return place


def _arc_to(path: np.ndarray, origin: int, point: np.ndarray) -> float:
    """Arc length along path (0 at path[origin]) of the path point nearest to point."""
    seg = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    return float(seg[int(np.argmin(np.linalg.norm(path - point, axis=1)))] - seg[origin])


def _trouser_placers(body: Body, made: Made, sections, outlines):
    fl, bl = outlines["front_l"], outlines["back_l"]
    hem_y = min(made.tops[n] / 100.0 + float(outlines[n][:, 1].min()) for n in made.legs)
    legs = LegSections(body, lowest=hem_y)
    vs = np.arange(float(min(fl[:, 1].min(), bl[:, 1].min())) - 0.01, 0.011, 0.01)
    half = _row_widths(fl, vs, 0.0) + _row_widths(bl, vs, 0.0)
    leg = _row_widths(fl, vs) + _row_widths(bl, vs)

    def half_girth(v):
        return float(np.interp(v, vs, half))

    def leg_girth(v):
        return float(np.interp(v, vs, leg))

    out = {}
    for n, plan in made.legs.items():
        side = made.hints[n].side
        top = made.tops[n] / 100.0

        def place(uv, plan=plan, side=side, top=top):
            return wrap_trousers(uv, side, plan.leg, top, plan.crotch_y, plan.crease, sections, legs,
                                 half_girth, leg_girth)

        out[n] = place
    return out
