"""How far round a part too small for the body is, against the body where it sits: a cuff that
GarmentCode cut to the wrist's girth on a sleeve ending on the upper arm, a waistband smaller than
the waist. The drape's error names such a part by its strain; these figures say it in centimetres
a user can check against the pattern (engine.scene.drape._open_seams).

    rings = part_girths(garment, x, ["cuff_f", "cuff_b"], body_vertices, body_faces)
    words = girth_words(rings)  # "at 'cuff_f', 'cuff_b' the cloth is 16.6 cm round (at rest) where ..."

The cloth is cut by planes square to the limb or trunk it wraps (the axis the body's normals
under it leave out); at each cut its length at rest (the panels' flat coordinates, so a stretched
or open ring reads as cut) is set against the girth of the body's piece inside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.measure import slice_pieces
from engine.garment.garment import Garment

UNDER = 0.025  # m: body faces this near the part's cloth are the surface it wraps
CUTS = 7  # planes across each part, along the axis
WRAPS = 0.5  # a cut counts where the cloth, as it lies, goes this share of the body's girth round
NEAR = 0.03  # m: cloth this near a piece of the body's cut lies round it
OWN = 0.2  # ... and the part's own cloth this share of it (not a sleeve's end beside the trunk)
SECTORS = 24  # directions round it: another panel's cloth counts where the part's own leaves one open


@dataclass
class Ring:
    """A group of tight panels sewn to each other, at the cut where the body is widest for it."""

    panels: list[str]
    rest: float  # m: the cloth's length round at rest at that cut (open seams left out)
    girth: float  # m: the body's girth there (a tape round it)

    @property
    def stretch(self) -> float:
        """The stretch the cloth needs to close round the body there."""
        return self.girth / self.rest - 1.0


def _groups(garment: Garment, names: list[str]) -> list[list[int]]:
    """The named panels' indices, grouped where a stitch joins them (a cuff's front and back)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    idx = [garment.panel_names.index(n) for n in names if n in garment.panel_names]
    n = len(garment.panel_names)
    pp = garment.panel[garment.seams] if len(garment.seams) else np.zeros((0, 2), int)
    pp = pp[np.isin(pp, idx).all(axis=1)]
    _, piece = connected_components(coo_matrix((np.ones(len(pp)), (pp[:, 0], pp[:, 1])), shape=(n, n)),
                                    directed=False)
    out: dict[int, list[int]] = {}
    for p in idx:
        out.setdefault(int(piece[p]), []).append(p)
    return list(out.values())


def _axis(body_v: np.ndarray, body_f: np.ndarray, pts: np.ndarray) -> np.ndarray | None:
    """The axis of the limb or trunk under the cloth `pts`: the direction the normals of the body
    faces within UNDER of it leave out (round a limb they turn all ways square to it)."""
    from scipy.spatial import cKDTree

    tri = body_v[body_f]
    centre = tri.mean(1)
    d, _ = cKDTree(pts).query(centre, distance_upper_bound=UNDER)
    near = np.isfinite(d)
    if near.sum() < 10:
        return None
    n = np.cross(tri[near, 1] - tri[near, 0], tri[near, 2] - tri[near, 0])  # (area-weighted)
    w, vec = np.linalg.eigh(n.T @ n)
    if w[1] < 0.2 * w[2]:  # (the normals do not turn round: the cloth lies on one side of the body)
        return None
    return vec[:, 0]


def _frame(axis: np.ndarray) -> np.ndarray:
    """(3, 3) rows: a unit vector square to axis, axis, another: the axis becomes "y"."""
    a = axis / np.linalg.norm(axis)
    e = np.eye(3)[int(np.argmin(np.abs(a)))]
    u = np.cross(a, e)
    u /= np.linalg.norm(u)
    return np.stack([u, a, np.cross(u, a)])


def _cloth_cut(h: np.ndarray, x: np.ndarray, uv: np.ndarray, tris: np.ndarray, y: float):
    """The cloth `tris` cut at height y of `h` (N,) (its positions along the axis): each cut
    segment's length as it lies (K,), at rest (K,), its middle (K, 3) and its triangle (K, 3)."""
    hy = h[tris] > y
    k = hy.sum(1)
    t = tris[(k == 1) | (k == 2)]
    if not len(t):
        return np.zeros(0), np.zeros(0), np.zeros((0, 3)), t
    a = h[t] > y
    ends3, ends2 = [], []
    for e in range(3):  # the two crossing edges of each cut triangle
        i, j = t[:, e], t[:, (e + 1) % 3]
        cross = a[:, e] != a[:, (e + 1) % 3]
        s = np.where(cross, (y - h[i]) / np.where(cross, h[j] - h[i], 1.0), 0.0)[:, None]
        ends3.append(np.where(cross[:, None], x[i] + s * (x[j] - x[i]), np.nan))
        ends2.append(np.where(cross[:, None], uv[i] + s * (uv[j] - uv[i]), np.nan))
    e3, e2 = np.stack(ends3, 1), np.stack(ends2, 1)  # (T, 3 edges, 3 | 2)
    ok = ~np.isnan(e3[:, :, 0])
    first, second = np.argmax(ok, 1), 2 - np.argmax(ok[:, ::-1], 1)
    r = np.arange(len(t))
    p, q = e3[r, first], e3[r, second]
    return np.linalg.norm(p - q, axis=1), np.linalg.norm(e2[r, first] - e2[r, second], axis=1), 0.5 * (p + q), t


def _round(mid: np.ndarray, cut_tris: np.ndarray, panel: np.ndarray, group: list[int], tree, centre: np.ndarray):
    """(K,) bool: the cut segments (middles `mid`, in the axis frame) of the cloth round the body's
    piece (`tree` of its points, `centre`): the group's own, and other panels' only in the
    directions round it that the group's cloth leaves open (a sleeve's other half; not the sleeve
    under a cuff)."""
    near = tree.query(mid[:, [0, 2]])[0] < NEAR
    d = mid[:, [0, 2]] - centre
    sector = ((np.arctan2(d[:, 1], d[:, 0]) + np.pi) / (2 * np.pi) * SECTORS).astype(np.int64) % SECTORS
    own = near & np.isin(panel[cut_tris[:, 0]], group)
    return own | (near & ~np.isin(sector, sector[own]))


def part_girths(garment: Garment, x: np.ndarray, names: list[str], body_v: np.ndarray,
                body_f: np.ndarray) -> list[Ring]:
    """For each group of the named panels sewn to each other (garment at positions x (N, 3)): the
    cut across it where the body is most too wide for the cloth round it (Ring) -- the cloth of
    every panel that lies round the body's piece inside the group there, a sleeve's other half
    too --, where that cloth wraps a limb or the trunk; groups that do not are left out.
    Tightest first."""
    from scipy.spatial import cKDTree

    tris = garment.triangles().astype(np.int64)
    body_v = np.asarray(body_v, dtype=np.float64)
    body_f = np.asarray(body_f, dtype=np.int64)
    rings = []
    for group in _groups(garment, names):
        mine = np.isin(garment.panel, group)
        t = tris[mine[tris].all(1)]
        if len(t) < 10:
            continue
        axis = _axis(body_v, body_f, x[mine])
        if axis is None:
            continue
        R = _frame(axis)
        xb, xc = body_v @ R.T, x @ R.T  # (the axis is y in this frame)
        h = xc[:, 1]
        # (a cloth edge in from its ends: a cut along a row of its vertices reads a part of the ring)
        edge = float(np.median(np.linalg.norm(x[t[:, 1]] - x[t[:, 0]], axis=1)))
        lo, hi = float(h[mine].min()) + edge, float(h[mine].max()) - edge
        best = None
        for y in (np.linspace(lo, hi, CUTS) if hi > lo else [0.5 * (lo + hi)]):
            _, _, own, _ = _cloth_cut(h, xc, garment.uv, t, float(y))
            pieces = slice_pieces(xb, body_f, float(y))
            if not len(own) or not pieces:
                continue
            trees = [cKDTree(p.points) for p in pieces]
            off = [float(np.median(tr.query(own[:, [0, 2]])[0])) for tr in trees]
            k = int(np.argmin(off))
            if off[k] > NEAR:
                continue
            lies, rest, mid, cut = _cloth_cut(h, xc, garment.uv, tris, float(y))
            on = _round(mid, cut, garment.panel, group, trees[k], pieces[k].centroid)
            girth = pieces[k].hull_perimeter
            own = np.isin(garment.panel[cut[:, 0]], group) & on
            if lies[on].sum() < WRAPS * girth or lies[own].sum() < OWN * girth or rest[on].sum() <= 0.0:
                continue
            ring = Ring([garment.panel_names[p] for p in group], float(rest[on].sum()), girth)
            if best is None or ring.stretch > best.stretch:
                best = ring
        if best is not None:
            rings.append(best)
    return sorted(rings, key=lambda r: -r.stretch)


def girth_words(rings: list[Ring], stretchiest: tuple[str, float] | None = None) -> str | None:
    """The tightest ring in words (None: none wider round the body than the cloth); stretchiest:
    (fabric, its threshold) -- the most any fabric here stretches, said where the ring needs more."""
    rings = [r for r in rings if r.stretch > 0.0]
    if not rings:
        return None
    r = rings[0]
    names = " and ".join(f"'{n}'" for n in r.panels[:2]) + (
        f" (and {len(r.panels) - 2} panel{'s' if len(r.panels) > 3 else ''} sewn to them)" if len(r.panels) > 2 else "")
    more = f" (and at {len(rings) - 1} more such part{'s' if len(rings) > 2 else ''})" if len(rings) > 1 else ""
    said = (f"at {names} the cloth is {100 * r.rest:.1f} cm round (at rest) where the body is "
            f"{100 * r.girth:.1f} cm round{more}: it would have to stretch {100 * r.stretch:.0f} % to close")
    if stretchiest is not None and r.stretch > stretchiest[1]:
        said += f", more than even {stretchiest[0]} does ({100 * stretchiest[1]:.0f} %)"
    return said
