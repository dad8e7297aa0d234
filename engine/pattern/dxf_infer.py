"""Infer a garment from a DXF pattern alone: which pieces make it, which edges sew together and
where each piece goes round the body (the DXF standard holds none of that).

1. Each piece gets a role from its category and name -- the codes pattern makers use (FR, BK,
   SL/SS/LS, CO/NR/RN/NB, CU, WB, YP/YL, IX/IY ...) and the words (front, back, sleeve, collar,
   cuff, waistband, binding, placket, interlining, leg ...), in their many spellings -- checked
   against its shape (a band is long and thin; the others are not).
2. Each piece is laid in its panel frame (see `Part`): a piece cut on the fold (a mirror line on
   its cut line) is unfolded; the grain line is turned vertical and the piece turned so that
   its top is up (a bodice's neck, a sleeve's cap, a leg's waist: `_top_up`).
3. Its outline is split at key points found from its shape (`_bodice_marks`, `_sleeve_marks`,
   `_leg_marks`): neck, shoulders, armholes, side seams, hem; sleeve cap (front and back half:
   the single notch marks the front, by convention), underarm seams, hem; leg waist, rises
   (the shorter one is the front), inseams, hem.
4. The seams follow from the roles: shoulders and side seams front to back, each sleeve's cap
   into its armhole and its underarm seam closed, the legs' inseams closed and their rises
   sewn to each other; bands (collar, neck rib or binding, cuffs, waistband, armhole binding)
   round the loop of edges they belong to (the neckline, a sleeve's hem, the waist ...).
Pieces a pattern maker marks as not cut in this model (quantity 0, where others are cut), and
alternatives for one role (two sleeves), are left out by a stated rule; so are plackets,
interlinings and pockets (the drape leaves the front closed). Where the inference is unsure
it says which pieces and why (`Inference.unsure`).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import numpy as np

from engine.errors import InputError
from engine.pattern import geometry as geo
from engine.pattern.dxf_read import DxfPattern, DxfPiece, corners_of

FOLD_TOL = 0.3  # cm: a mirror line within this of the cut line is a fold
CORNER_DEG = 50.0  # a turn sharper than this is a corner even where the file does not break the line
MERGE_CM = 0.3  # cm: cut positions closer than this are one
BAND_ASPECT = 3.5  # a piece this many times longer than wide ...
BAND_WIDTH = 16.0  # cm: ... and at most this wide is a band (collar, cuff, binding, waistband)
SLEEVE_EASE = 1.04  # a sleeve's cap is cut this much longer than its armhole (about)

# role -> (words looked for inside the category's and the name's words, codes matched whole)
ROLE_WORDS = {
    "cuff": (("CUFF", "MANSCH", "POIGNET", "PUNO"), ("CU", "CUF")),
    "collar": (("COLLAR", "NECK", "KRAGEN", "COL", "RIB"), ("CO", "NR", "RN", "NB", "NK", "NKB")),
    "waistband": (("WAISTBAND", "WAIST", "BUND", "CEINTURE", "PRETINA"), ("WB", "WBD")),
    "binding": (("BINDING", "BIND", "TAPE"), ("AB", "BD", "BND")),
    "interlining": (("INTERLIN", "FUSING", "FUSE", "EINLAGE", "ENTOIL"), ("IX", "IY", "IN", "FU")),
    "placket": (("PLACKET", "PLKT", "FACING", "BLENDE"), ("YP", "YL", "PL", "PLK", "FC")),
    "pocket": (("POCKET", "TASCHE", "POCHE", "BOLSILLO"), ("PK", "PKT", "PO")),
    "sleeve": (("SLEEVE", "ARMEL", "MANCHE", "MANGA"), ("SL", "SLV", "SS", "LS", "SLS", "SLL")),
    "leg": (("LEG", "PANT", "TROUSER", "LEGGING", "TIGHT", "HOSE"), ("LL", "LG")),
    "front": (("FRONT", "VORDER", "DEVANT", "DELANT"), ("FR", "FRT", "FT", "F")),
    "back": (("BACK", "RUECK", "RUCK", "HINTER", "DOS", "ESPALD"), ("BK", "BCK", "BA", "B")),
}
BAND_ROLES = ("cuff", "collar", "waistband", "binding")
LEFT_OUT_ROLES = {"placket": "a placket is sewn over a slit cut in the front, which the drape leaves closed",
                  "interlining": "an interlining is fused inside another piece, not sewn as cloth of its own",
                  "pocket": "a pocket lies flat on another piece; the drape leaves it out"}


@dataclass
class Part:
    """A panel of the garment, in its panel frame (cm): a bodice piece's top centre (the height
    of its highest point, on its centre line) at (0, 0), u > 0 toward the wearer's left; a
    sleeve's cap top at (0, 0), v < 0 toward the hem, u > 0 toward the front; a leg's waist top
    at v = 0, its side line (the grain line) at u = 0 and its front toward +u on the left leg
    (-u on the right); a band as laid out (its placement follows the loop it is sewn to).
    marks: named arc-length positions (cm from outline[0], forward)."""

    name: str
    piece: str
    role: str  # front, back, sleeve, leg, or a band role
    outline: np.ndarray  # (M, 2) cm
    corners: list[int]
    notches: np.ndarray  # (K, 2) cm, on or near the outline
    marks: dict[str, float] = field(default_factory=dict)
    side: str | None = None  # 'left' / 'right' for sleeves, legs and cuffs
    unfolded: bool = False
    mirrored: bool = False  # a mirrored copy of the piece (the second of a pair cut twice)
    grain: np.ndarray | None = None
    pair: bool = False  # the second of a pair cut twice (pair_copy)
    stretch: float = 1.0  # a band's length, x its cut length (fit_band)

    @property
    def length(self) -> float:
        return float(_arc(self.outline)[-1])


@dataclass
class Span:
    """An interval of a part's outline: from arc position s0 to s1 (cm), forward (dir +1, through
    the outline's start if need be) or backward (dir -1)."""

    part: str
    s0: float
    s1: float
    dir: int = 1

    def length(self, total: float) -> float:
        return ((self.s1 - self.s0) * self.dir) % total or (total if self.s0 == self.s1 else 0.0)

    def at(self, f: float, total: float) -> float:
        return (self.s0 + self.dir * f * self.length(total)) % total


@dataclass
class Seam:
    """Two spans sewn together, their starts meeting (and their ends)."""

    a: Span
    b: Span
    label: str


@dataclass
class Inference:
    parts: list[Part]
    seams: list[Seam]
    kind: str  # 'top', 'bottom' or 'pieces' (nothing to sew could be inferred)
    notes: list[str] = field(default_factory=list)
    unsure: list[str] = field(default_factory=list)
    left_out: list[str] = field(default_factory=list)

    def part(self, name: str) -> Part:
        return next(p for p in self.parts if p.name == name)


# ------------------------------------------------------------------ small geometry


def _arc(pts: np.ndarray, closed: bool = True) -> np.ndarray:
    """Arc length at each point (and, closed, at the return to the first: len(pts) + 1)."""
    q = np.vstack([pts, pts[:1]]) if closed else pts
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))])


def point_at(pts: np.ndarray, s: float) -> np.ndarray:
    """The point at arc position s of a closed outline."""
    a = _arc(pts)
    s = s % a[-1]
    q = np.vstack([pts, pts[:1]])
    return np.array([np.interp(s, a, q[:, 0]), np.interp(s, a, q[:, 1])])


def span_points(pts: np.ndarray, span: Span) -> np.ndarray:
    """(K, 2) the outline's points along a span, its ends interpolated, in the span's direction."""
    a = _arc(pts)
    total = a[-1]
    n = span.length(total)
    inner = [(s - span.s0) * span.dir % total for s in a[:-1]]
    keep = sorted((d, i) for i, d in enumerate(inner) if 1e-9 < d < n - 1e-9)
    mid = [pts[i] for _, i in keep]
    return np.array([point_at(pts, span.s0), *mid, point_at(pts, span.s1)])


def _turn_deg(pts: np.ndarray) -> np.ndarray:
    """Turn angle (degrees) of a closed outline at each vertex."""
    prev, nxt = pts - np.roll(pts, 1, axis=0), np.roll(pts, -1, axis=0) - pts
    cos = (prev * nxt).sum(1) / np.maximum(np.linalg.norm(prev, axis=1) * np.linalg.norm(nxt, axis=1), 1e-18)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _rotate(pts: np.ndarray, ang: float) -> np.ndarray:
    c, s = np.cos(ang), np.sin(ang)
    return pts @ np.array([[c, s], [-s, c]])


def min_rect(pts: np.ndarray) -> tuple[float, float, float]:
    """(long side, short side, angle of the long side) of the smallest rectangle round the points
    (over the convex hull's edge directions)."""
    from scipy.spatial import ConvexHull

    try:
        hull = pts[ConvexHull(pts).vertices]
    except Exception:  # degenerate: a line
        hull = pts
    best = None
    for k in range(len(hull)):
        d = hull[(k + 1) % len(hull)] - hull[k]
        ang = float(np.arctan2(d[1], d[0]))
        r = _rotate(hull, -ang)
        w, h = np.ptp(r, axis=0)
        if best is None or w * h < best[0]:
            best = (w * h, w, h, ang)
    _, w, h, ang = best
    return (w, h, ang) if w >= h else (h, w, ang + np.pi / 2)


# ------------------------------------------------------------------ roles


def _tokens(text: str) -> list[str]:
    return [t for t in re.split(r"[^A-Z]+", text.upper()) if t]


def name_codes(pattern: DxfPattern) -> dict[str, list[str]]:
    """Each piece's name less the style's prefix that all its pieces share, as words."""
    names = [p.name for p in pattern.pieces]
    prefix = os.path.commonprefix(names) if len(names) > 1 else ""
    if pattern.style and all(n.upper().startswith(pattern.style.upper()) for n in names):
        prefix = pattern.style if len(pattern.style) > len(prefix) else prefix
    return {n: _tokens(n[len(prefix):] if len(prefix) >= 3 else n) for n in names}


def _roles_in(words: list[str], codes: bool) -> list[str]:
    found = []
    for role, (long, short) in ROLE_WORDS.items():
        if any(lw in w for w in words for lw in long) or (codes and any(w in short for w in words)):
            found.append(role)
    return found


def piece_role(piece: DxfPiece, codes: list[str], band: bool) -> tuple[str | None, str]:
    """(role or None, why) from the category's words, else the name's codes and words, checked
    against the shape (band: long and thin)."""
    cat = _roles_in(_tokens(piece.category or ""), codes=False)
    name = _roles_in(codes, codes=True)
    # the most specific first: a 'SLEEVE CUFF' is a cuff, a 'NECK RIB' a collar, 'FRONT HALF CO' a front
    for source, found in (("category", cat), ("name", name)):
        fits = [r for r in found if (r in BAND_ROLES) == band or r in LEFT_OUT_ROLES]
        if fits:
            return fits[0], f"{source} '{piece.category if source == 'category' else piece.name}'"
    if band:
        return "band", "its shape (a long, narrow strip)"
    return None, "neither its name nor its category names a garment part"


# ------------------------------------------------------------------ panel frames


def _fold_of(o: np.ndarray, mirror: list[np.ndarray]) -> tuple[int, int] | None:
    """(i, j): outline indices of a mirror line's ends when the cut line o runs along it from i
    to j (forward) -- the piece is cut on the fold there; else None."""
    for m in mirror:
        d = m[1] - m[0]
        L = float(np.linalg.norm(d))
        if L < 1.0:
            continue
        ends = [int(np.linalg.norm(o - m[k], axis=1).argmin()) for k in (0, 1)]
        if min(np.linalg.norm(o[ends[0]] - m[0]), np.linalg.norm(o[ends[1]] - m[1])) > FOLD_TOL * 3:
            continue
        off = np.abs((o[:, 0] - m[0, 0]) * d[1] - (o[:, 1] - m[0, 1]) * d[0]) / L
        for i, j in (ends, ends[::-1]):
            run = np.arange(i, i + (j - i) % len(o) + 1) % len(o)
            if len(run) >= 2 and off[run].max() <= FOLD_TOL and (j - i) % len(o) < len(o) - 2:
                return i, j
    return None


def _unfold(outline: np.ndarray, corners: list[int], notches: np.ndarray, fold: tuple[int, int]):
    """The whole piece from its half cut on the fold (outline indices i -> j along the fold):
    the rest of the outline (j -> i) and its mirror image; the fold's ends stay corners only
    where the whole outline turns there (a V neck)."""
    i, j = fold
    n = len(outline)
    keep = np.arange(j, j + (i - j) % n + 1) % n  # j ... i, off the fold
    half = outline[keep]
    a, b = outline[i], outline[j]
    d = (b - a) / np.linalg.norm(b - a)

    def mirror(p):
        r = p - a
        return a + 2 * np.outer(r @ d, d) - r

    whole = np.vstack([half, mirror(half)[::-1][1:-1]])
    m = len(half)
    pos = {int(k): idx for idx, k in enumerate(keep)}
    cs = [pos[c] for c in corners if c in pos]
    cs = sorted(set(cs + [(2 * (m - 1) - c) % len(whole) for c in cs if 0 < c < m - 1]))
    turn = _turn_deg(whole)
    cs = [c for c in cs if c not in (0, m - 1) or turn[c] > CORNER_DEG / 2]
    near = np.abs(((notches - a) @ np.array([-d[1], d[0]]))) < FOLD_TOL if len(notches) else np.zeros(0, bool)
    notches = np.vstack([notches, mirror(notches[~near])]) if len(notches) else notches
    return whole, cs, notches


def _to_grain(pts: np.ndarray, grain: np.ndarray | None) -> tuple[np.ndarray, float]:
    """Turned so the grain line is vertical (the long axis where there is none): (points, angle)."""
    if grain is not None and np.linalg.norm(grain[1] - grain[0]) > 0.5:
        d = grain[1] - grain[0]
        ang = float(np.arctan2(d[1], d[0]))
    else:
        ang = min_rect(pts)[2]
    return _rotate(pts, ang - np.pi / 2), ang - np.pi / 2


def _neck_drop(o: np.ndarray, cx: float) -> tuple[float, float]:
    """(top's drop, bottom's drop): how far below its highest point the outline crosses the line
    u = cx at the top, and above its lowest point at the bottom."""
    a, b = o, np.roll(o, -1, axis=0)
    cross = (a[:, 0] - cx) * (b[:, 0] - cx) <= 0
    t = np.clip((cx - a[cross, 0]) / np.where(b[cross, 0] != a[cross, 0], b[cross, 0] - a[cross, 0], 1.0), 0, 1)
    ys = a[cross, 1] + t * (b[cross, 1] - a[cross, 1])
    if not len(ys):
        return 0.0, 0.0
    return float(o[:, 1].max() - ys.max()), float(ys.min() - o[:, 1].min())


def _width_near(o: np.ndarray, end: str, frac: float = 0.08) -> float:
    """The outline's width (u extent) over the last `frac` of its height at one end."""
    lo, hi = o[:, 1].min(), o[:, 1].max()
    h = hi - lo
    sel = o[:, 1] >= hi - frac * h if end == "top" else o[:, 1] <= lo + frac * h
    return float(np.ptp(o[sel, 0])) if sel.sum() > 1 else 0.0


def _top_up(o: np.ndarray, role: str) -> bool:
    """Whether the piece (grain vertical) already has its top up: a bodice's neck (the centre
    line meets the top below its highest point, the hem at its lowest), a sleeve's cap (narrower
    than its hem end), a leg's waist (wider than its hem)."""
    if role in ("front", "back", "bodice"):
        cx = 0.5 * (o[:, 0].min() + o[:, 0].max())
        top, bottom = _neck_drop(o, cx)
        return top >= bottom
    narrow_top = _width_near(o, "top") <= _width_near(o, "bottom")
    return narrow_top if role == "sleeve" else not narrow_top


def make_part(name: str, piece: DxfPiece, size: str, role: str) -> Part:
    """The piece in its panel frame (see Part), before its marks."""
    shape = piece.shapes[size]
    outline, corners = corners_of(piece, size)
    notches = shape.notches.copy()
    if shape.sew is not None and len(notches):  # notches cut into the allowance: onto the sew line
        near = np.linalg.norm(notches[:, None] - outline[None], axis=2)
        notches = outline[near.argmin(axis=1)][near.min(axis=1) < 2.5]
    fold = _fold_of(outline, shape.mirror)
    unfolded = fold is not None
    if unfolded:
        outline, corners, notches = _unfold(outline, corners, notches, fold)
    grain = shape.grain if shape.grain is not None else np.zeros((0, 2))
    both = np.vstack([outline, notches.reshape(-1, 2), grain])
    turned, ang = _to_grain(both, shape.grain)
    n_o, n_n = len(outline), len(notches)
    outline, notches, grain = turned[:n_o], turned[n_o:n_o + n_n], turned[n_o + n_n:]
    if role not in BAND_ROLES and not _top_up(outline, role):
        outline, notches, grain = -outline, -notches, -grain
    if geo.signed_area(outline) < 0:  # counter-clockwise (mirror_part makes the clockwise ones)
        outline = _reverse(outline)
        corners = sorted({(len(outline) - c) % len(outline) for c in corners})
    return Part(name=name, piece=piece.name, role=role, outline=outline, corners=corners, notches=notches,
                unfolded=unfolded, grain=grain if len(grain) == 2 else None)


def mirror_part(p: Part, name: str | None = None) -> Part:
    """The part mirrored left to right (u -> -u), its points in the same order (so its corners
    and marks stay) and so wound the other way: a back as seen from behind."""
    flip = np.array([-1.0, 1.0])
    return Part(name=name or p.name, piece=p.piece, role=p.role, outline=p.outline * flip, corners=list(p.corners),
                notches=p.notches * flip, marks=dict(p.marks), side=p.side, unfolded=p.unfolded,
                mirrored=not p.mirrored, grain=None if p.grain is None else p.grain * flip)


def reflect(p: Part) -> Part:
    """The part mirrored left to right and still counter-clockwise (its marks to be found again)."""
    n = len(p.outline)
    q = mirror_part(p)
    q.outline = _reverse(q.outline)
    q.corners = sorted({(n - c) % n for c in p.corners})
    q.marks = {}
    return q


def _reverse(o: np.ndarray) -> np.ndarray:
    """The outline the other way round from the same first point: the point at arc position s
    comes to total - s."""
    return np.roll(o[::-1], 1, axis=0).copy()


def pair_copy(p: Part, name: str, side: str | None = None) -> Part:
    """The other piece of a pair cut twice: the same outline with the fabric's other face out
    (its points in reverse order, so wound the other way), marks carried over."""
    n, total = len(p.outline), p.length
    return Part(name=name, piece=p.piece, role=p.role, outline=_reverse(p.outline),
                corners=sorted({(n - c) % n for c in p.corners}), notches=p.notches.copy(),
                marks={k: (total - s) % total for k, s in p.marks.items()}, side=side, unfolded=p.unfolded,
                mirrored=not p.mirrored, grain=p.grain, pair=True, stretch=p.stretch)


def _shift(p: Part, du: float, dv: float) -> None:
    p.outline = p.outline + np.array([du, dv])
    if len(p.notches):
        p.notches = p.notches + np.array([du, dv])
    if p.grain is not None:
        p.grain = p.grain + np.array([du, dv])


def _arcpos(p: Part) -> np.ndarray:
    return _arc(p.outline)[:-1]


# ------------------------------------------------------------------ key points


def _corner_pos(p: Part) -> tuple[np.ndarray, np.ndarray]:
    """(outline indices of the corners, their (K, 2) points)."""
    idx = np.array(p.corners, dtype=int)
    return idx, p.outline[idx]


def _span(p: Part, a: float, b: float, avoid: float) -> Span:
    """The span from arc position a to b that does not pass over position `avoid`."""
    total = p.length
    fwd = (b - a) % total
    return Span(p.name, a, b, 1 if (avoid - a) % total > fwd else -1)


def _extreme_corner(p: Part, cand: np.ndarray, score) -> int:
    """The candidate corner (outline indices) of the highest score; the highest point among
    those within 0.5 cm of it."""
    pts = p.outline[cand]
    sc = np.array([score(q) for q in pts])
    near = cand[sc >= sc.max() - 0.5]
    return int(near[np.argmax(p.outline[near, 1])])


def _between(p: Part, a: int, b: int, d: int) -> np.ndarray:
    """Corner indices strictly between outline indices a and b walking in direction d."""
    n = len(p.outline)
    idx, _ = _corner_pos(p)
    steps = ((idx - a) * d) % n
    end = ((b - a) * d) % n
    return idx[(steps > 0) & (steps < end)]


def _outward(p: Part, i: int, sign: float) -> int:
    """The direction (+1/-1 along the outline) in which the outline leaves point i away from the
    centre line (toward sign * u)."""
    n = len(p.outline)
    ahead = p.outline[(i + 1) % n, 0] - p.outline[i, 0]
    back = p.outline[(i - 1) % n, 0] - p.outline[i, 0]
    return 1 if sign * ahead >= sign * back else -1


def bodice_marks(p: Part) -> None:
    """A front's or back's key points (p.marks, arc positions) and its frame: centre line at u = 0,
    highest point at v = 0. hps_l/r: the highest point each side (the neck meets the shoulder);
    sp: the shoulder's far end (the next corner outward); up: the underarm point (the corner
    furthest out between the shoulder and the hem corner; the highest of those within 5 mm);
    hc: the hem corner (the outermost corner within 3 cm of the bottom)."""
    o = p.outline
    _shift(p, -0.5 * (o[:, 0].min() + o[:, 0].max()), -o[:, 1].max())
    o = p.outline
    arc = _arcpos(p)
    idx, pts = _corner_pos(p)
    low = o[:, 1].min()
    for side, sign in (("l", 1.0), ("r", -1.0)):
        half = np.flatnonzero(sign * o[:, 0] > 0.5)
        if not len(half):
            raise InputError(f"piece '{p.piece}': no {'left' if side == 'l' else 'right'} half to find its shoulder")
        top = o[half, 1].max()
        hps = int(half[np.argmin(np.where(o[half, 1] >= top - 0.1, np.abs(o[half, 0]), np.inf))])
        d = _outward(p, hps, sign)
        hc_cand = idx[(sign * pts[:, 0] > 0) & (pts[:, 1] <= low + 3.0)]
        if not len(hc_cand):
            raise InputError(f"piece '{p.piece}': no hem corner on its {'left' if side == 'l' else 'right'}")
        hc = _extreme_corner(p, hc_cand, lambda q: sign * q[0])
        on_way = _between(p, hps, hc, d)
        if len(on_way) < 2:
            raise InputError(f"piece '{p.piece}': too few corners between its neck and hem to find the shoulder "
                             "and the armhole")
        steps = ((on_way - hps) * d) % len(o)
        sp = int(on_way[np.argmin(steps)])
        rest = _between(p, sp, hc, d)
        up = _extreme_corner(p, rest, lambda q: sign * q[0]) if len(rest) else sp
        for key, i in (("hps", hps), ("sp", sp), ("up", up), ("hc", hc)):
            p.marks[f"{key}_{side}"] = float(arc[i])
    # the centre line's crossings at the top (neck) and bottom (hem)
    p.marks["cn"] = _crossing(p, top=True)
    p.marks["ch"] = _crossing(p, top=False)


def _crossing(p: Part, top: bool) -> float:
    """Arc position where the outline crosses u = 0 highest (top) or lowest."""
    o = p.outline
    a, b = o, np.roll(o, -1, axis=0)
    cross = np.flatnonzero((a[:, 0] <= 0) != (b[:, 0] <= 0))
    t = -a[cross, 0] / (b[cross, 0] - a[cross, 0])
    ys = a[cross, 1] + t * (b[cross, 1] - a[cross, 1])
    k = int(np.argmax(ys) if top else np.argmin(ys))
    arc = _arc(o)
    i = cross[k]
    return float(arc[i] + t[k] * (arc[i + 1] - arc[i]))


def bodice_spans(p: Part) -> dict[str, Span]:
    m = p.marks
    out = {"neck": _span(p, m["hps_r"], m["hps_l"], m["ch"]), "hem": _span(p, m["hc_l"], m["hc_r"], m["cn"])}
    for s in ("l", "r"):
        out[f"shoulder_{s}"] = _span(p, m[f"hps_{s}"], m[f"sp_{s}"], m[f"up_{s}"])
        out[f"armhole_{s}"] = _span(p, m[f"sp_{s}"], m[f"up_{s}"], m[f"hps_{s}"])
        out[f"side_{s}"] = _span(p, m[f"up_{s}"], m[f"hc_{s}"], m[f"sp_{s}"])
    return out


def sleeve_marks(p: Part) -> tuple[Part, bool]:
    """(the sleeve with its key points and frame, whether its notches said which half of the cap
    is the front). Key points: apex (the cap's top, its shoulder notch where there is one), cap
    ends uf/ub, hem corners hf/hb; frame: apex at (0, 0), the front half at u > 0 -- the half
    with the single notch (a pattern maker's convention: one notch front, two back), else the
    +u half as drawn."""
    if _sleeve_marks(p):
        p = reflect(p)
        _sleeve_marks(p)
        return p, True
    front_known = bool(p.marks.pop("_known"))
    return p, front_known


def _sleeve_marks(p: Part) -> bool:
    """sleeve_marks' key points; returns whether the front is at -u (so the part must be reflected)."""
    o = p.outline
    arc = _arcpos(p)
    apex = int(np.argmax(o[:, 1]))
    if len(p.notches):
        d = np.linalg.norm(p.notches - o[apex], axis=1)
        if d.min() < 3.0:  # the shoulder notch
            apex = int(np.linalg.norm(o - p.notches[d.argmin()], axis=1).argmin())
    _shift(p, -o[apex, 0], -o[apex, 1])
    o = p.outline
    idx, pts = _corner_pos(p)
    low = o[:, 1].min()
    found = {}
    for key, sign in (("f", 1.0), ("b", -1.0)):
        hc_cand = idx[(sign * pts[:, 0] > 0.5) & (pts[:, 1] <= low + 3.0)]
        if not len(hc_cand):
            raise InputError(f"piece '{p.piece}': no hem corner on one side of its sleeve cap")
        hc = _extreme_corner(p, hc_cand, lambda q: sign * q[0])
        d = _outward(p, apex, sign)
        rest = _between(p, apex, hc, d)
        cap_end = _extreme_corner(p, rest, lambda q: sign * q[0]) if len(rest) else hc
        found[key] = (hc, cap_end, d)
    p.marks.update(apex=float(arc[apex]), hf=float(arc[found["f"][0]]), uf=float(arc[found["f"][1]]),
                   hb=float(arc[found["b"][0]]), ub=float(arc[found["b"][1]]))
    counts = {}
    for key in ("f", "b"):
        cap = span_points(o, _span(p, p.marks["apex"], p.marks[f"u{key}"], p.marks[f"h{key}"]))
        from_cap = np.array([_dist_to(q, cap) for q in p.notches]) if len(p.notches) else np.zeros(0)
        away = np.linalg.norm(p.notches, axis=1) > 1.0 if len(p.notches) else np.zeros(0, bool)
        counts[key] = int(((from_cap < 0.5) & away).sum())
    known = {counts["f"], counts["b"]} == {1, 2} or (min(counts.values()) == 0 and max(counts.values()) == 1)
    p.marks["_known"] = float(known)
    return known and counts["b"] == 1 and counts["f"] != 1  # the single notch is the front's: turn it to +u


def _dist_to(q: np.ndarray, poly: np.ndarray) -> float:
    a, b = poly[:-1], poly[1:]
    ab = b - a
    t = np.clip(((q - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-18), 0, 1)
    return float(np.linalg.norm(a + t[:, None] * ab - q, axis=1).min())


def sleeve_spans(p: Part) -> dict[str, Span]:
    m = p.marks
    return {"cap_f": _span(p, m["apex"], m["uf"], m["hf"]), "cap_b": _span(p, m["apex"], m["ub"], m["hb"]),
            "under_f": _span(p, m["uf"], m["hf"], m["apex"]), "under_b": _span(p, m["ub"], m["hb"], m["apex"]),
            "hem": _span(p, m["hf"], m["hb"], m["apex"])}


def leg_marks(p: Part) -> Part:
    """A one-piece leg's key points: waist corners wf/wb (the highest corner each side of the
    grain line), crotch points cf/cb (the corners furthest out), hem corners hf/hb (the lowest
    each side); the front is the side whose rise (waist to crotch) is shorter, turned to +u.
    Frame: waist top at v = 0, the grain line at u = 0."""
    o = p.outline
    gx = float(p.grain[:, 0].mean()) if p.grain is not None else 0.5 * (o[:, 0].min() + o[:, 0].max())
    _shift(p, -gx, -o[:, 1].max())
    o = p.outline
    arc = _arcpos(p)
    idx, pts = _corner_pos(p)
    low = o[:, 1].min()
    got = {}
    for key, sign in (("p", 1.0), ("n", -1.0)):
        sel = idx[sign * pts[:, 0] > 0]
        if len(sel) < 3:
            raise InputError(f"piece '{p.piece}': too few corners on one side to find its waist, crotch and hem")
        waist = int(sel[np.argmax(o[sel, 1])])
        crotch = _extreme_corner(p, sel, lambda q: sign * q[0])
        hem_cand = sel[o[sel, 1] <= low + 3.0]
        hem = _extreme_corner(p, hem_cand if len(hem_cand) else sel, lambda q: -q[1])
        got[key] = (waist, crotch, hem)
    rise = {k: _span(p, arc[w], arc[c], arc[h]).length(p.length) for k, (w, c, h) in got.items()}
    if rise["n"] < rise["p"]:  # the front (the shorter rise) at -u: reflect, then find them again
        return leg_marks(reflect(p))
    for name, key in (("f", "p"), ("b", "n")):
        w, c, h = got[key]
        p.marks.update({f"w{name}": float(arc[w]), f"c{name}": float(arc[c]), f"h{name}": float(arc[h])})
    return p


def leg_spans(p: Part) -> dict[str, Span]:
    m = p.marks
    return {"waist": _span(p, m["wf"], m["wb"], m["hf"]), "hem": _span(p, m["hf"], m["hb"], m["wf"]),
            "rise_f": _span(p, m["wf"], m["cf"], m["hf"]), "rise_b": _span(p, m["wb"], m["cb"], m["hb"]),
            "inseam_f": _span(p, m["cf"], m["hf"], m["wf"]), "inseam_b": _span(p, m["cb"], m["hb"], m["wb"])}


def band_spans(p: Part) -> dict[str, Span]:
    """A band's sewn side, free side and ends: the long sides run between the four corners
    nearest the corners of its smallest rectangle; the sewn one is the long side with more
    notches (shoulder or centre marks), else the first."""
    o = p.outline
    arc = _arcpos(p)
    L, W, ang = min_rect(o)
    r = _rotate(o, ang)
    lo, hi = r.min(axis=0), r.max(axis=0)
    box = [np.array([lo[0], lo[1]]), np.array([hi[0], lo[1]]), np.array([hi[0], hi[1]]), np.array([lo[0], hi[1]])]
    four = []
    for idx in (np.array(p.corners, dtype=int), np.arange(len(o))):  # its corners, else any of its points
        if len(idx) >= 4:
            four = sorted({int(idx[np.linalg.norm(r[idx] - c, axis=1).argmin()]) for c in box})
        if len(four) == 4:
            break
    if len(four) < 4:
        raise InputError(f"piece '{p.piece}': a band whose four corners could not be told apart")
    sides = [Span(p.name, float(arc[four[k]]), float(arc[four[(k + 1) % 4]]), 1) for k in range(4)]
    lengths = [s.length(p.length) for s in sides]
    longs = sorted(range(4), key=lambda k: -lengths[k])[:2]
    longs.sort()
    notch_n = []
    for k in longs:
        pts = span_points(o, sides[k])
        notch_n.append(sum(_dist_to(q, pts) < 0.5 for q in p.notches))
    sewn, free = (longs[0], longs[1]) if notch_n[0] >= notch_n[1] else (longs[1], longs[0])
    e1, e2 = (sewn + 1) % 4, (sewn + 3) % 4  # the ends: after the sewn side, and before it
    s = sides[sewn]
    end1 = sides[e1]  # from the sewn side's end to the free side
    end2 = Span(p.name, sides[e2].s1, sides[e2].s0, -1)  # from the sewn side's start to the free side
    return {"sewn": s, "free": sides[free], "end_a": end2, "end_b": end1}


# ------------------------------------------------------------------ the garment


def _len(p: Part, span: Span) -> float:
    return span.length(p.length)


def _split_span(p: Part, span: Span, at: float) -> tuple[Span, Span]:
    return Span(p.name, span.s0, at, span.dir), Span(p.name, at, span.s1, span.dir)


RIB_TENSION = 0.97  # a band much shorter than its loop (a rib) is cut to this share of it
BAND_SLACK = 0.06  # a band within this share of its loop's length is sewn as cut


def fit_band(band: Part, loop_length: float) -> str | None:
    """A band shorter than its loop by more than BAND_SLACK (a rib collar or cuff: rib knit
    stretches onto the edge as it is sewn, which this cloth does not) is stretched lengthwise to
    RIB_TENSION of the loop; one longer is cut to the loop's length. Returns a note, or None."""
    sewn = band_spans(band)["sewn"].length(band.length)
    ratio = sewn / loop_length
    if abs(ratio - 1.0) <= BAND_SLACK:
        return None
    target = RIB_TENSION if ratio < 1.0 else 1.0
    stretch_band(band, target / ratio)
    return (f"{band.piece}: {100 * ratio:.0f} % of the {loop_length:.1f} cm edge it is sewn to; lengthened to "
            f"{100 * target:.0f} % for the drape (a rib stretches as it is sewn on; the cloth simulated does not)"
            if ratio < 1.0 else f"{band.piece}: {100 * ratio:.0f} % of the {loop_length:.1f} cm edge it is sewn "
            "to; shortened to its length for the drape")


def stretch_band(band: Part, k: float) -> None:
    """The band lengthened k times along its long side."""
    if k == 1.0:
        return
    _, _, ang = min_rect(band.outline)
    r = _rotate(band.outline, ang)
    r[:, 0] *= k
    band.outline = _rotate(r, -ang)
    band.stretch *= k


def frame_part(name: str, piece: DxfPiece, size: str, role: str, side: str | None = None, pair: bool = False,
               stretch: float = 1.0) -> Part:
    """A piece as a panel of the given role (see Part: the frame, the key points), the second of
    a pair (pair_copy) or a band lengthened (stretch_band) as asked."""
    p = make_part(name, piece, size, role)
    if role == "back":
        p = mirror_part(p)
    if role in ("front", "back"):
        bodice_marks(p)
    elif role == "sleeve":
        p, _ = sleeve_marks(p)
    elif role == "leg":
        p = leg_marks(p)
    else:
        stretch_band(p, stretch)
    p.side = side
    return pair_copy(p, name, side) if pair else p


def band_seams(band: Part, loop: list[tuple[Part, Span]], ring: bool, label: str) -> tuple[list[Seam], float]:
    """A band's sewn side round a loop of spans (split in the loop's proportions), its ends sewn
    together when it is a ring; (seams, band length / loop length as cut)."""
    sp = band_spans(band)
    total = band.length
    sewn = sp["sewn"]
    lengths = np.array([_len(p, s) for p, s in loop])
    fr = np.concatenate([[0.0], np.cumsum(lengths) / lengths.sum()])
    seams = [Seam(Span(band.name, sewn.at(fr[k], total), sewn.at(fr[k + 1], total), sewn.dir), s, f"{label} {k + 1}")
             for k, (_, s) in enumerate(loop)]
    if ring:
        seams.append(Seam(sp["end_a"], sp["end_b"], f"{label} ends"))
    return seams, _len(band, sewn) / float(lengths.sum())


@dataclass
class _Pick:
    piece: DxfPiece
    role: str
    why: str


def classify_pieces(pattern: DxfPattern, size: str) -> tuple[dict[str, list[_Pick]], dict[str, list[_Pick]], list[str]]:
    """(role -> pieces cut in this model, role -> alternatives not cut in it, notes on the others)."""
    codes = name_codes(pattern)
    counted = any((p.quantity or 0) > 0 for p in pattern.pieces)
    used: dict[str, list[_Pick]] = {}
    spare: dict[str, list[_Pick]] = {}
    left = []
    for piece in pattern.pieces:
        if size not in piece.shapes:
            left.append(f"{piece.name}: not graded in size {size}")
            continue
        L, W, _ = min_rect(piece.shapes[size].outline)
        role, why = piece_role(piece, codes[piece.name], L >= BAND_ASPECT * W and W <= BAND_WIDTH)
        if role is None:
            left.append(f"{piece.name}: {why}")
            continue
        if role in LEFT_OUT_ROLES:
            left.append(f"{piece.name} ({role}, by its {why}): {LEFT_OUT_ROLES[role]}")
            continue
        pick = _Pick(piece, role, why)
        if counted and piece.quantity == 0:
            spare.setdefault(role, []).append(pick)
        else:
            used.setdefault(role, []).append(pick)
    return used, spare, left


def _halves(pick: _Pick, pattern: DxfPattern) -> bool:
    """A sleeve cut in two (its name or category also says front or back)."""
    words = name_codes(pattern)[pick.piece.name] + _tokens(pick.piece.category or "")
    return bool(_roles_in(words, codes=True) and {"front", "back"} & set(_roles_in(words, codes=True)))


def infer(pattern: DxfPattern, size: str) -> Inference:
    """The garment of a DXF pattern in one of its sizes (see the module doc)."""
    if size not in pattern.sizes:
        raise InputError(f"{pattern.source}: no size '{size}' (its sizes: {', '.join(pattern.sizes)})")
    used, spare, left = classify_pieces(pattern, size)
    left += [f"{p.piece.name} ({p.role}): quantity 0, not cut in this model (an alternative)"
             for ps in spare.values() for p in ps]
    inf = Inference(parts=[], seams=[], kind="pieces", left_out=left)
    if (used.get("front") and used.get("back")) or used.get("leg"):
        kind = "top" if used.get("front") and used.get("back") else "bottom"
        try:
            (_top if kind == "top" else _bottom)(inf, used, spare, pattern, size)
        except InputError as e:  # the pieces do not read as such a garment: imported as they are
            inf.parts, inf.seams, inf.kind = [], [], "pieces"
            inf.unsure.append(f"the pieces read as a {kind} by their names, but {e}: no seams are inferred -- "
                              "give an assembly file")
    else:
        inf.unsure.append("no front and back, and no leg pieces, were recognised: the pieces are imported but "
                          "no seams could be inferred -- name the pieces' roles in the pattern software (front, "
                          "back, sleeve, collar, cuff, waistband, leg) or give an assembly file")
    cut = {q.piece for q in inf.parts}
    inf.notes = [f"{p.piece.name}: {p.role} (by its {p.why})" for ps in [*used.values(), *spare.values()]
                 for p in ps if p.piece.name in cut] + inf.notes
    return inf


def _first(inf: Inference, picks: list[_Pick], role: str) -> _Pick:
    if len(picks) > 1:
        inf.left_out += [f"{p.piece.name} ({role}): an alternative to {picks[0].piece.name} "
                         "(the first in the file is used)" for p in picks[1:]]
    return picks[0]


def _check(inf: Inference, label: str, la: float, lb: float, tol: float = 0.08) -> None:
    if abs(la - lb) > tol * max(la, lb):
        inf.unsure.append(f"{label}: the edges sewn together differ in length ({la:.1f} and {lb:.1f} cm)")


def _top(inf: Inference, used, spare, pattern: DxfPattern, size: str) -> None:
    inf.kind = "top"
    f = make_part("front", _first(inf, used["front"], "front").piece, size, "front")
    b = mirror_part(make_part("back", _first(inf, used["back"], "back").piece, size, "back"))
    bodice_marks(f)
    bodice_marks(b)
    inf.parts += [f, b]
    fs, bs = bodice_spans(f), bodice_spans(b)
    for s in ("l", "r"):
        for edge in ("shoulder", "side"):
            key = f"{edge}_{s}"
            label = f"{edge} ({'left' if s == 'l' else 'right'})"
            inf.seams.append(Seam(fs[key], bs[key], label))
            _check(inf, label, _len(f, fs[key]), _len(b, bs[key]))
    sleeves = _optional(inf, "sleeves", lambda: _sleeves(inf, used, spare, pattern, size, f, b)) or []
    if sleeves:
        _optional(inf, "cuffs", lambda: _cuffs(inf, used, size, sleeves))
    elif used.get("binding") or used.get("cuff"):
        inf.left_out += [f"{p.piece.name} ({p.role}): armhole bindings of a sleeveless top are not "
                         "inferred" for p in used.get("binding", []) + used.get("cuff", [])]
    _optional(inf, "collar", lambda: _collar(inf, used, size, f, b))


def _optional(inf: Inference, what: str, add):
    """add() the parts and seams of an optional part of the garment; where its pieces cannot be
    read as one (InputError), the garment goes without it and says why."""
    parts, seams = list(inf.parts), list(inf.seams)
    try:
        return add()
    except InputError as e:
        inf.parts, inf.seams = parts, seams
        inf.unsure.append(f"{what} left out: {e}")
        return None


def _sleeves(inf, used, spare, pattern, size, f: Part, b: Part) -> list[Part]:
    whole = [p for p in used.get("sleeve", []) if not _halves(p, pattern)]
    halves = [p for p in used.get("sleeve", []) if _halves(p, pattern)]
    if halves:
        msg = (f"{', '.join(p.piece.name for p in halves)}: a sleeve cut in two pieces, which is not inferred")
        alt = [p for p in spare.get("sleeve", []) if not _halves(p, pattern)]
        if not whole and alt:
            whole = alt
            msg += f"; the one-piece sleeve {alt[0].piece.name} (quantity 0) is used instead"
            inf.left_out = [x for x in inf.left_out if not x.startswith(f"{alt[0].piece.name} ")]
        inf.left_out.append(msg)
    if not whole:
        return []
    fs, bs = bodice_spans(f), bodice_spans(b)
    armhole = _len(f, fs["armhole_l"]) + _len(b, bs["armhole_l"])
    best = None
    for pick in whole:
        part, known = sleeve_marks(make_part("sleeve_r", pick.piece, size, "sleeve"))
        sp = sleeve_spans(part)
        ratio = (_len(part, sp["cap_f"]) + _len(part, sp["cap_b"])) / armhole
        if best is None or abs(ratio - SLEEVE_EASE) < abs(best[2] - SLEEVE_EASE):
            best = (pick, part, ratio, known)
    pick, right, ratio, known = best
    inf.left_out += [f"{p.piece.name} (sleeve): {pick.piece.name}'s cap fits the armholes better"
                     for p in whole if p is not pick]
    inf.notes.append(f"{pick.piece.name}: sleeve cap {ratio * armhole:.1f} cm into armholes of {armhole:.1f} cm "
                     f"({100 * (ratio - 1):+.0f} % ease)")
    if not 0.9 <= ratio <= 1.25:
        inf.unsure.append(f"{pick.piece.name}: its cap ({ratio * armhole:.1f} cm) does not fit the armholes "
                          f"({armhole:.1f} cm) -- is it the sleeve of this garment?")
    if not known:
        inf.unsure.append(f"{pick.piece.name}: no single notch tells the front of the cap from the back; the cap is "
                          "sewn as drawn")
    right.side = "right"
    left = pair_copy(right, "sleeve_l", "left")
    inf.parts += [left, right]
    for s, part in (("l", left), ("r", right)):
        sp = sleeve_spans(part)
        side = "left" if s == "l" else "right"
        inf.seams += [Seam(sp["cap_f"], fs[f"armhole_{s}"], f"sleeve cap, front ({side})"),
                      Seam(sp["cap_b"], bs[f"armhole_{s}"], f"sleeve cap, back ({side})"),
                      Seam(sp["under_f"], sp["under_b"], f"underarm ({side})")]
        _check(inf, f"underarm ({side})", _len(part, sp["under_f"]), _len(part, sp["under_b"]))
    return [left, right]


def _cuffs(inf, used, size, sleeves: list[Part]) -> None:
    cuffs = used.get("cuff", [])
    if not cuffs:
        return
    pick = _first(inf, cuffs, "cuff")
    for sl in sleeves:
        cuff = make_part(f"cuff_{sl.side[0]}", pick.piece, size, "cuff")
        cuff.side = sl.side
        if sl.side == "left":
            cuff = pair_copy(cuff, cuff.name, "left")
        hem = sleeve_spans(sl)["hem"]
        ratio = band_spans(cuff)["sewn"].length(cuff.length) / _len(sl, hem)
        note = fit_band(cuff, _len(sl, hem))
        seams, _ = band_seams(cuff, [(sl, hem)], ring=True, label=f"cuff ({sl.side})")
        inf.parts.append(cuff)
        inf.seams += seams
    inf.notes.append(note or f"{pick.piece.name}: cuff, {100 * ratio:.0f} % of the sleeve's hem")


def _collar(inf, used, size, f: Part, b: Part) -> None:
    picks = used.get("collar", [])
    if not picks:
        return
    fs = bodice_spans(f)
    b_l = _span(b, b.marks["cn"], b.marks["hps_l"], b.marks["ch"])
    b_r = _span(b, b.marks["hps_r"], b.marks["cn"], b.marks["ch"])
    f_n = Span(f.name, fs["neck"].s1, fs["neck"].s0, -fs["neck"].dir)  # left to right
    loop = [(b, b_l), (f, f_n), (b, b_r)]
    total = sum(_len(p, s) for p, s in loop)
    best = min(picks, key=lambda p: abs(min_rect(p.piece.shapes[size].outline)[0] - 0.9 * total))
    inf.left_out += [f"{p.piece.name} (collar): {best.piece.name}'s length fits the neckline better"
                     for p in picks if p is not best]
    collar = make_part("collar", best.piece, size, "collar")
    ratio = band_spans(collar)["sewn"].length(collar.length) / total
    note = fit_band(collar, total)
    seams, _ = band_seams(collar, loop, ring=True, label="collar")
    inf.parts.append(collar)
    inf.seams += seams
    inf.notes.append(f"{best.piece.name}: collar round a neckline of {total:.1f} cm ({100 * ratio:.0f} % of it), "
                     "its ends sewn at the centre back")
    if note:
        inf.notes.append(note)
    if not 0.6 <= ratio <= 1.3:
        inf.unsure.append(f"{best.piece.name}: {100 * ratio:.0f} % of the neckline's length -- is it this "
                          "garment's collar?")


def _bottom(inf: Inference, used, spare, pattern: DxfPattern, size: str) -> None:
    inf.kind = "bottom"
    picks = used["leg"]
    pick = max(picks, key=lambda p: float(np.ptp(p.piece.shapes[size].outline, axis=0).max()))
    inf.left_out += [f"{p.piece.name} (leg): an alternative length; the longest, {pick.piece.name}, "
                     "is used" for p in picks if p is not pick]
    left = leg_marks(make_part("leg_l", pick.piece, size, "leg"))
    left.side = "left"
    right = pair_copy(left, "leg_r", "right")
    inf.parts += [left, right]
    ls, rs = leg_spans(left), leg_spans(right)
    for part, sp, side in ((left, ls, "left"), (right, rs, "right")):
        inf.seams.append(Seam(sp["inseam_f"], sp["inseam_b"], f"inseam ({side})"))
        _check(inf, f"inseam ({side})", _len(part, sp["inseam_f"]), _len(part, sp["inseam_b"]))
    inf.seams += [Seam(ls["rise_f"], rs["rise_f"], "front rise"), Seam(ls["rise_b"], rs["rise_b"], "back rise")]
    _optional(inf, "waistband", lambda: _waistband(inf, used, size, left, right, ls, rs))


def _waistband(inf: Inference, used, size: str, left: Part, right: Part, ls: dict, rs: dict) -> None:
    bands = used.get("waistband", [])
    if bands:
        band_pick = _first(inf, bands, "waistband")
        band = make_part("waistband", band_pick.piece, size, "waistband")
        loop = [(left, Span(left.name, ls["waist"].s1, ls["waist"].s0, -ls["waist"].dir)), (right, rs["waist"])]
        total = sum(_len(p, s) for p, s in loop)
        ratio = band_spans(band)["sewn"].length(band.length) / total
        note = fit_band(band, total)
        seams, _ = band_seams(band, loop, ring=True, label="waistband")
        inf.parts.append(band)
        inf.seams += seams
        inf.notes.append(note or f"{band_pick.piece.name}: waistband, {100 * ratio:.0f} % of the waist")


def hints_of(parts: list[Part]) -> dict:
    """The placement hint (engine.pattern.spec.PanelHint) of each part."""
    from engine.pattern.spec import PanelHint

    out = {}
    for p in parts:
        pts = {k: tuple(round(float(c), 3) for c in point_at(p.outline, s)) for k, s in p.marks.items()
               if not k.startswith("_")}
        if p.role in ("front", "back"):
            out[p.name] = PanelHint(region="torso", side=p.role, role="bodice", points=pts)
        elif p.role == "sleeve":
            out[p.name] = PanelHint(region=f"{p.side}_arm", side="around", role="sleeve", points=pts)
        elif p.role == "leg":
            out[p.name] = PanelHint(region=f"{p.side}_leg", side="around", role="leg", points=pts)
        else:
            region = {"cuff": f"{p.side}_arm", "waistband": "hips"}.get(p.role, "torso")
            out[p.name] = PanelHint(region=region, side="around", role="band")
    return out
