"""Place a garment inferred from a DXF pattern (engine.pattern.dxf_infer: its panels carry a
`role` and key points in their `tryon.placement` hints) round a body, as the catalogue's
garments are placed:
- a front or back is wrapped round the torso (wrap_torso), its highest point 1 cm above the
  side of the body's neck, straight up from its underarm points (clamp_y);
- a sleeve is wrapped round its arm from the shoulder point of the bodice it is sewn to (the
  catalogue's sleeve placer: tubes round the arm's bent axis, the cap's top at the shoulder);
- a one-piece leg (front and back in one, its side line on the grain line) wraps the torso
  above its crotch and its own leg below (wrap_trousers, each half from its own centre line),
  the crotch 2 cm below the body's;
- a band (collar, cuff, waistband) follows the loop of edges it is sewn to, once those are
  placed: each band point goes to the point of the loop its sewn edge meets, and out from there
  as far as it lies from that edge, continuing the surface it is sewn to (a collar stands up
  from the neckline, a cuff carries on down the arm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.types import Body
from engine.errors import InputError
from engine.garment.place import CLEARANCE, BodySections, LegSections, wrap_torso
from engine.pattern import geometry as geo
from engine.pattern.spec import PanelHint, PatternSpec

CROTCH_BELOW = 0.02  # m: a leg's crotch point is placed this far below the body's
N_BAND = 24  # segments per sewn edge when a band is laid along its loop


def has_roles(spec: PatternSpec) -> bool:
    """Whether the spec's panels all carry a DXF inference's roles (then dxf_placement places it)."""
    hints = spec.tryon.placement if spec.tryon is not None else {}
    return bool(hints) and all(n in hints and hints[n].role is not None for n in spec.pattern.panels)


def _pt(hint: PanelHint, key: str, scale: float) -> np.ndarray:
    if key not in hint.points:
        raise InputError(f"the pattern's placement hint has no point '{key}' (import the DXF again)")
    return np.asarray(hint.points[key], dtype=np.float64) * scale


class _Body:
    """What the placement needs of the body: landmarks (world heights, m), sections, arms."""

    def __init__(self, body: Body):
        from engine.body.measure import measure
        from engine.pattern.catalogue import neck_half_width, _side_neck_height

        self.body = body
        m = measure(body)
        floor = float(body.vertices[:, 1].min())
        need = {"shoulder": m.shoulder_height, "armpit": m.armpit_height, "crotch": m.crotch_height,
                "knee": m.knee_height}
        bad = [k for k, v in need.items() if not np.isfinite(v)]
        if bad:
            raise InputError(f"the body's landmarks ({', '.join(bad)}) could not be measured; a garment needs "
                             "them to be placed (check `tryon body info`)")
        self.m, self.floor = m, floor
        self.shoulder, self.armpit = floor + m.shoulder_height, floor + m.armpit_height
        self.crotch, self.knee = floor + m.crotch_height, floor + m.knee_height
        nw = 0.045 * m.height  # the catalogue's neckline side point (engine.pattern.catalogue._fit)
        nh = _side_neck_height(body, nw, self.shoulder)
        if neck_half_width(body, nh + 0.01) + 0.01 > nw:
            nh = _side_neck_height(body, neck_half_width(body, nh + 0.01) + 0.01, self.shoulder)
        self.neck = max(self.shoulder + 0.04, nh + 0.01)
        self.sections = BodySections(body, cover=True)
        self._arms = None

    def arms(self) -> tuple[Body, dict]:
        """(the body whose arm vertices to use, arm joints per side): the rig's, or the default
        skeleton's fitted to a scan (as the catalogue's sleeves)."""
        if self._arms is None:
            from engine.pattern.catalogue import arm_joints, chart_of

            joints, arm_body = arm_joints(self.body), self.body
            if joints is None:
                from engine.body.fit import fit_rig

                arm_body = fit_rig(self.body, "male" if chart_of(self.body, self.m) == "men" else "female")
                joints = arm_joints(arm_body)
            if joints is None:
                raise InputError("sleeves need the body's arm axes, and no skeleton could be fitted to this body")
            self._arms = (arm_body, joints)
        return self._arms


def dxf_placement(spec: PatternSpec, body: Body):
    """(place(name, panel, uv) -> (n, 3) world points, a note) for a spec with DXF roles."""
    hints = spec.tryon.placement
    scale = spec.scale
    b = _Body(body)
    panels = spec.pattern.panels
    outlines = {n: geo.outline(p, scale) for n, p in panels.items()}
    roles = {n: hints[n].role for n in panels}
    placers: dict = {}
    sleeves = [n for n, r in roles.items() if r == "sleeve"]
    for n, r in roles.items():
        if r == "bodice":
            placers[n] = _bodice(hints[n], outlines[n], b, scale, lean=True)
    legs = [n for n, r in roles.items() if r == "leg"]
    if legs:
        placers.update(_legs(legs, hints, outlines, b, scale))
    for n in sleeves:
        placers[n] = _sleeve(n, spec, hints, placers, outlines[n], b)
    for n, r in roles.items():
        if r == "band":
            placers[n] = _band(n, spec, placers)

    def place(name, panel, uv):
        return placers[name](uv)

    return place, "placed from the pattern's inferred roles (front, back, sleeves, legs, bands)"


# ------------------------------------------------------------------ bodice and sleeves


def _bodice(hint: PanelHint, outline: np.ndarray, b: _Body, scale: float, lean: bool):
    under = min(_pt(hint, "up_l", scale)[1], _pt(hint, "up_r", scale)[1])
    clamp = min(b.neck + under, b.armpit)

    def place(uv):
        return wrap_torso(uv, hint, b.sections, b.neck, outline, clamp_y=clamp, lean=lean)

    return place


def _sewn_to(spec: PatternSpec, name: str) -> list[tuple[int, str, int]]:
    """(edge of `name`, other panel, its edge) for every stitch between `name` and another panel."""
    out = []
    for a, c in spec.pattern.stitches:
        if a.panel == name and c.panel != name:
            out.append((a.edge, c.panel, c.edge))
        elif c.panel == name and a.panel != name:
            out.append((c.edge, a.panel, a.edge))
    return out


def _sleeve(name: str, spec: PatternSpec, hints, placers, outline: np.ndarray, b: _Body):
    """The catalogue's sleeve placer, the cap's top at the shoulder point of the bodice panels
    its cap is sewn to (their points sp_l / sp_r, as placed)."""
    from engine.garment.catalogue import _sleeve_placer
    from engine.pattern.catalogue import SleevePlan

    side = "left" if hints[name].region == "left_arm" else "right"
    key = "sp_l" if side == "left" else "sp_r"
    bodices = sorted({o for _, o, _ in _sewn_to(spec, name) if hints[o].role == "bodice"})
    if not bodices:
        raise InputError(f"sleeve '{name}' is sewn to no front or back: the assembly cannot place it")
    sp = np.mean([placers[o](_pt(hints[o], key, spec.scale)[None])[0] for o in bodices], axis=0)
    arm_body, joints = b.arms()
    j = joints[side]
    cap_top = np.array([sp[0], max(sp[1], b.shoulder) + 0.01, j[0, 2]])
    placer = _sleeve_placer(arm_body, SleevePlan(side, cap_top, j), outline)
    return placer


# ------------------------------------------------------------------ legs


@dataclass
class LegFrame:
    """What wrap_leg needs of a one-piece leg panel (metres, its frame): its outline, its front
    and back waist points (where the rises start), the world heights of its waist top and crotch."""

    outline: np.ndarray
    wf: np.ndarray
    wb: np.ndarray
    top: float
    crotch_y: float
    knee_v: float = -np.inf  # below this panel height the rows are drawn up (heights)
    squeeze: float = 1.0  # ... by this factor, so that the hem stays above the foot

    def height(self, v: np.ndarray) -> np.ndarray:
        """World heights of panel rows v."""
        v = np.asarray(v, dtype=np.float64)
        return self.top + np.where(v >= self.knee_v, v, self.knee_v + self.squeeze * (v - self.knee_v))

    def centres(self, v: float) -> tuple[float, float]:
        """u of the centre back and centre front lines at height v: the rises, straight up above
        their waist points."""
        lo, hi = geo.row_extent(self.outline, np.array([v]))
        u_b = float(lo[0]) if v <= self.wb[1] else float(self.wb[0])
        u_f = float(hi[0]) if v <= self.wf[1] else float(self.wf[0])
        return u_b, u_f


def _legs(names: list[str], hints, outlines, b: _Body, scale: float) -> dict:
    """One-piece legs (panel frame: waist top at v = 0, the side line at u = 0, front toward +u),
    placed by wrap_leg, the crotch CROTCH_BELOW under the body's."""
    o = outlines[names[0]]
    h = hints[names[0]]
    crotch_v = min(float(_pt(h, "cf", scale)[1]), float(_pt(h, "cb", scale)[1]))
    top = b.crotch - CROTCH_BELOW - crotch_v
    frame = LegFrame(o, _pt(h, "wf", scale), _pt(h, "wb", scale), top, top + crotch_v)
    hem_v = float(o[:, 1].min())
    floor = _hem_floor(LegSections(b.body, lowest=1.0), o, hem_v)  # (the legs' own cuts: no tube round the foot)
    if top + hem_v < floor:  # longer than the leg: drawn up below the knee, to bunch at the ankle
        frame.knee_v = b.knee - top
        frame.squeeze = (b.knee - floor) / max(b.knee - top - hem_v, 1e-3)
    legs = LegSections(b.body, lowest=float(frame.height(np.array([hem_v]))[0]))

    def placer(side: str):
        def place(uv):
            return wrap_leg(uv, side, frame, b.sections, legs)

        return place

    return {n: placer("left" if hints[n].region == "left_leg" else "right") for n in names}


HEM_STRETCH = 1.10  # a hem may start round the leg stretched this much


def _hem_floor(legs: LegSections, outline: np.ndarray, hem_v: float) -> float:
    """The lowest height (m) where a leg's hem fits round the body's leg: the leg's covering
    girth there at most HEM_STRETCH x the hem's width (below the ankle the foot grows fast:
    a legging's 21 cm hem placed 4 cm above the floor was stretched 39 %)."""
    from engine.garment.place import _half_perimeter

    lo, hi = geo.row_extent(outline, np.array([hem_v + 0.005]))
    hem = float(hi[0] - lo[0])
    ys = np.arange(0.02, 0.45, 0.005)
    ell = legs.at(ys, 1)
    girth = np.array([2 * _half_perimeter(a, bb) for _, _, a, bb, _ in ell])
    fits = np.flatnonzero(girth <= HEM_STRETCH * hem)
    return float(ys[fits[0]]) if len(fits) else float(ys[-1])


LEG_BLEND = 0.10  # m above the crotch over which a leg goes from its own leg's tube to the torso's


def wrap_leg(uv: np.ndarray, side: str, f: LegFrame, torso: BodySections, legs: LegSections) -> np.ndarray:
    """(n, 2) points of a one-piece leg (metres; v = 0 at the waist top, u = 0 on the side line,
    front toward +u) -> (n, 3) round the body. Below the crotch each row goes round its own leg's
    ellipse from the leg's outer side, the front half forward and the back half backward, its
    width spread over the whole way round (a legging cut smaller than the leg starts stretched
    onto it, its inseams met); above the crotch the row spans the torso's half ellipse on its
    side from the centre back line to the centre front line (LegFrame.centres) in proportion,
    so the rises lie on the body's centre lines and meet the other leg's; in between
    (LEG_BLEND) the two are blended, as wrap_trousers blends. The ellipses are the covering
    cross-sections grown by CLEARANCE (and to the row's width, where it is wider)."""
    from engine.garment.place import _ellipse_arcs, _ellipse_point, _half_perimeter

    sgn = 1.0 if side == "left" else -1.0
    leg = 1 if side == "left" else -1
    u, v = uv[:, 0], uv[:, 1]
    y = f.height(v)
    rows = np.round(v / 0.01).astype(int)
    out_t, out_l = np.zeros((len(uv), 3)), np.zeros((len(uv), 3))
    for r in np.unique(rows):
        sel = rows == r
        yr = float(f.height(np.array([r * 0.01]))[0])
        lo, hi = geo.row_extent(f.outline, np.array([r * 0.01]))
        width = max(float(hi[0] - lo[0]), 1e-3)
        u_b, u_f = f.centres(r * 0.01)
        cx, cz, a, bb, kc = torso.at(np.array([max(yr, f.crotch_y)]), grown=True)[0]
        a, bb = a + CLEARANCE, bb + CLEARANCE
        k = max(1.0 / kc, (u_f - u_b) / _half_perimeter(a, bb))
        a, bb = a * k, bb * k
        t = np.clip((u[sel] - u_b) / max(u_f - u_b, 1e-3), 0.0, 1.0)  # CB 0 .. CF 1
        sn, cs = _ellipse_point(a, bb, sgn * (1.0 - t) * _half_perimeter(a, bb),
                                _ellipse_arcs(np.array([a]), np.array([bb]))[0])
        out_t[sel] = np.stack([cx + a * sn, y[sel], cz + bb * cs], axis=1)
        cx, cz, a, bb, kc = legs.at(np.array([min(yr, f.crotch_y)]), leg)[0]
        a, bb = a + CLEARANCE, bb + CLEARANCE
        k = max(1.0 / kc, width / (2 * _half_perimeter(a, bb)))
        a, bb = a * k, bb * k
        arcs = _ellipse_arcs(np.array([a]), np.array([bb]))[0]
        quarter = float(np.interp(np.pi / 2, np.linspace(-np.pi, np.pi, len(arcs)), arcs))
        spread = 2 * _half_perimeter(a, bb) / width
        half = 0.5 * (arcs[-1] - arcs[0])  # the arcs run from -half (theta -pi) to +half: wrap into them
        sn, cs = _ellipse_point(a, bb, (sgn * (quarter - spread * u[sel]) + half) % (2 * half) - half, arcs)
        out_l[sel] = np.stack([cx + a * sn, y[sel], cz + bb * cs], axis=1)
    g = np.clip((y - f.crotch_y) / LEG_BLEND, 0.0, 1.0)[:, None] ** 0.9
    return g * out_t + (1 - g) * out_l


# ------------------------------------------------------------------ bands


def _band(name: str, spec: PatternSpec, placers: dict):
    """A band along the loop it is sewn to: its sewn edges, in their order round the band, meet
    the other panels' edges, each placed the way round that joins them into one line."""
    scale = spec.scale
    panels = spec.pattern.panels
    panel = panels[name]
    sewn = sorted((e, o, oe) for e, o, oe in _sewn_to(spec, name) if o in placers)
    if not sewn:
        raise InputError(f"band '{name}' is sewn to no other panel: the assembly cannot place it")
    chain = _chain([e for e, _, _ in sewn], panel)
    partner = {e: (o, oe) for e, o, oe in sewn}
    band_2d, loop_3d, away_3d = [], [], []
    for e in chain:
        band_2d.append(geo.edge_samples(panel, panel.edges[e], scale, N_BAND))
        o, oe = partner[e]
        pts, away = _edge_placed(panels[o], oe, placers[o], scale)
        loop_3d.append(pts)
        away_3d.append(away)
    owners = [partner[e][0] for e in chain]
    _orient(loop_3d, away_3d, [(partner[e][0], partner[e][1], len(panels[partner[e][0]].edges)) for e in chain])
    _close_loop(loop_3d, owners)

    def place(uv):
        k, t, d = _project(uv, band_2d)
        out = np.zeros((len(uv), 3))
        for i in range(len(chain)):
            sel = k == i
            if sel.any():
                s = t[sel] * N_BAND
                p = np.stack([np.interp(s, np.arange(N_BAND + 1), loop_3d[i][:, c]) for c in range(3)], axis=1)
                a = np.stack([np.interp(s, np.arange(N_BAND + 1), away_3d[i][:, c]) for c in range(3)], axis=1)
                a /= np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-12)
                out[sel] = p + d[sel, None] * a
        return out

    return place


def _chain(edges: list[int], panel) -> list[int]:
    """The sewn edges in their order round the band (the run that does not wrap past a free edge)."""
    n = len(panel.edges)
    s = set(edges)
    start = next((e for e in edges if (e - 1) % n not in s), edges[0])
    out = [start]
    while (out[-1] + 1) % n in s and (out[-1] + 1) % n != start:
        out.append((out[-1] + 1) % n)
    return out


def _edge_placed(panel, edge: int, place, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """(N_BAND + 1, 3) points of a placed panel's edge, and the direction (per point) in which
    its surface carries on past the edge."""
    uv = geo.edge_samples(panel, panel.edges[edge], scale, N_BAND)
    d = np.gradient(uv, axis=0)
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    left = np.stack([-d[:, 1], d[:, 0]], axis=1)
    ccw = geo.signed_area(geo.outline(panel, scale)) > 0
    inward = left if ccw else -left
    p, q = place(uv), place(uv + 0.02 * inward)
    return p, p - q


def _orient(loop: list[np.ndarray], away: list[np.ndarray], partners: list[tuple[str, int, int]]) -> None:
    """Each partner edge turned (in place) to run the way the band runs along it. Within a run of
    consecutive edges of one panel (partners: (panel, edge, the panel's edge count)) the way is
    the run's: forward when the band meets its edges in their own order. A run of one edge
    turns to start where the edge before it ends, or to end where the next starts (the first
    edge of a loop of one: as it is)."""
    n = len(loop)
    for k, j in _runs([q[0] for q in partners]):
        if j > k:
            step = (partners[k + 1][1] - partners[k][1]) % partners[k][2]
            reverse = step != 1
        elif n == 1:
            reverse = False
        else:
            prev, nxt = loop[k - 1] if k > 0 else None, loop[k + 1] if k + 1 < n else None
            if prev is not None:
                reverse = np.linalg.norm(prev[-1] - loop[k][-1]) < np.linalg.norm(prev[-1] - loop[k][0])
            else:
                reverse = np.linalg.norm(nxt[0] - loop[k][0]) < np.linalg.norm(nxt[0] - loop[k][-1])
        if reverse:
            for i in range(k, j + 1):
                loop[i], away[i] = loop[i][::-1], away[i][::-1]


def _runs(owners: list[str]) -> list[tuple[int, int]]:
    """(first, last) index of each run of consecutive loop edges of one panel."""
    runs, k = [], 0
    while k < len(owners):
        j = k
        while j + 1 < len(owners) and owners[j + 1] == owners[k]:
            j += 1
        runs.append((k, j))
        k = j + 1
    return runs


def _close_loop(loop: list[np.ndarray], owners: list[str]) -> None:
    """Where the loop passes from one panel's edges to the next panel's, the two panels start
    apart until the seam between them is sewn (a neckline's front and back halves, 25-35 cm
    apart at the shoulder seams): each run of one panel's edges is bent (in place), its ends
    moved to the middle of each gap and the moves spread along it by arc length, so the band
    is laid where those seams will close, not across their gaps."""
    runs = _runs(owners)
    if len(runs) < 2:
        return
    ends = [(loop[k][0].copy(), loop[j][-1].copy()) for k, j in runs]
    for r, (k, j) in enumerate(runs):
        before, after = ends[r - 1][1] if r > 0 else None, ends[r + 1][0] if r + 1 < len(runs) else None
        d0 = np.zeros(3) if before is None else 0.5 * (before - ends[r][0])
        d1 = np.zeros(3) if after is None else 0.5 * (after - ends[r][1])
        pts = np.concatenate([loop[i] for i in range(k, j + 1)])
        seg = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        f = seg / max(seg[-1], 1e-12)
        at = 0
        for i in range(k, j + 1):
            n = len(loop[i])
            loop[i] += (1 - f[at:at + n, None]) * d0 + f[at:at + n, None] * d1
            at += n


def _project(uv: np.ndarray, lines: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each point's nearest place on the polylines: (which line, fraction along it, distance)."""
    best_d = np.full(len(uv), np.inf)
    k_out, t_out = np.zeros(len(uv), dtype=int), np.zeros(len(uv))
    for k, line in enumerate(lines):
        a, c = line[:-1], line[1:]
        ab = c - a
        t = np.clip(((uv[:, None, :] - a[None]) * ab[None]).sum(2) / np.maximum((ab * ab).sum(1), 1e-18)[None],
                    0, 1)
        d = np.linalg.norm(a[None] + t[..., None] * ab[None] - uv[:, None, :], axis=2)
        j = d.argmin(axis=1)
        dmin = d[np.arange(len(uv)), j]
        better = dmin < best_d
        best_d[better] = dmin[better]
        k_out[better] = k
        t_out[better] = (j[better] + t[np.arange(len(uv)), j][better]) / (len(line) - 1)
    return k_out, t_out, best_d
