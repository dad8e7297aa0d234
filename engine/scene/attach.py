"""GarmentCode's attachments: its simulator keeps some labelled edges of a pattern from sliding
while the panels are sewn -- the top of a lower garment ("lower_interface") and of a strapless
top ("strapless_top") from sliding down the body, a collar's ends ("right_collar",
"left_collar") from sliding off the neck -- each vertex on one side of a plane (a one-sided
constraint) for its first 400 frames, about its whole simulation. Here the same
(engine.cloth.welds.hold_on_planes): each labelled vertex kept from going below (or, a
collar's, further out than) where the placement put it -- the pattern's own placement on the
body it was made for, else the one carried onto this body by its landmarks
(engine.garment.place) -- while the garment is sewn and draped: a skirt with no waistband is
held at its waist as its tie or elastic would hold it. Such a top with no waistband, cut far
wider round than the body where it is held (GarmentCode's rectangle and flared skirts), is
gathered onto an elastic (Elastic), as a maker sews one: held alone it stood off the body as a
tube."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.types import Body
from engine.cloth.config import Attachment
from engine.errors import TryonError
from engine.garment.garment import Garment

# how firmly each label is held: (s to bring a vertex back to its plane, at most m/s)
HOLD = {"lower_interface": (0.05, 1.0), "strapless_top": (0.05, 1.0), "right_collar": (0.1, 0.3),
        "left_collar": (0.1, 0.3)}
SLACK = 0.01  # m: a held vertex may settle this far below (outside) where it was placed
NECK_INSIDE = 0.01  # m: a collar's ends kept no further out than this inside the neck's half width
# a held top sewn to nothing, this much longer round than the body where it is held, is gathered
# onto an elastic ELASTIC_EASE longer round than the body there (top_elastic)
ELASTIC_PAST = 0.10
ELASTIC_EASE = 0.03


@dataclass(frozen=True)
class Elastic:
    """An elastic sewn into a garment's held top (engine.cloth.model.with_elastic on its model)."""

    vertices: np.ndarray  # (K,) the top's vertices (unsewn)
    factor: float  # the elastic's length / the cloth's along the top
    cloth: float  # m: the cloth round the top
    body: float  # m: the body round where it is held

    @property
    def note(self) -> str:
        return (f"its top ('lower_interface'), cut {100 * self.cloth:.0f} cm round with no waistband where the "
                f"body is {100 * self.body:.0f} cm round, is gathered onto an elastic "
                f"{100 * self.factor * self.cloth:.0f} cm round, as a maker would sew it (held as cut, it would "
                "stand off the body)")


def attachment(garment: Garment, body: Body) -> tuple[Attachment | None, str | None]:
    """The attachment of the garment's labelled edges on this body, and what the report says of
    it (None, None: no labelled edge)."""
    from engine.body.measure import measure
    from engine.pattern.catalogue import neck_half_width

    x = garment.positions
    idx, points, normals, tau, vmax, said = [], [], [], [], [], []

    def hold(label: str, v: np.ndarray, p: np.ndarray, n: tuple, what: str) -> None:
        idx.append(v)
        points.append(p)
        normals.append(np.tile(n, (len(v), 1)))
        tau.append(np.full(len(v), HOLD[label][0]))
        vmax.append(np.full(len(v), HOLD[label][1]))
        said.append(f"'{label}' {what}")

    elastic = None
    for label in ("lower_interface", "strapless_top"):
        v = garment.labelled.get(label)
        if v is not None and len(v) and _round_body(body, x[v]):
            hold(label, v, x[v] - [0.0, SLACK, 0.0], (0.0, 1.0, 0.0), "from sliding down")
            if label == "lower_interface" and (elastic := top_elastic(garment, body, v)) is not None:
                # (nor above: an elastic pulled in rides up a body that narrows above where it is put
                # -- a band 3 cm deep climbed from the waist to under the bust -- where a worn one stays)
                hold(label, v, x[v] + [0.0, SLACK, 0.0], (0.0, -1.0, 0.0), "")
                said.pop()  # (said with the elastic: GarmentCode's simulator holds no edge so)
    collar = [lb for lb in ("right_collar", "left_collar") if len(garment.labelled.get(lb, ()))]
    if collar:
        try:  # the neck's half width just above the shoulders: the bound a collar end keeps inside
            half = neck_half_width(body, measure(body).shoulder_height + 0.05) - NECK_INSIDE
        except TryonError:
            half = np.nan
        for label in collar:
            v = garment.labelled[label]
            side = -1.0 if label == "right_collar" else 1.0  # GarmentCode's right is the body's -x
            out = side * x[v, 0]  # how far out each vertex was placed
            bound = np.maximum(out, half) if np.isfinite(half) else out
            p = np.zeros((len(v), 3))
            p[:, 0] = side * (bound + SLACK)
            hold(label, v, p, (-side, 0.0, 0.0), "from sliding off the neck")
    if not idx:
        return None, None
    att = Attachment(vertices=np.concatenate(idx).astype(np.int64), points=np.concatenate(points),
                     normals=np.concatenate(normals).astype(np.float64), tau=np.concatenate(tau),
                     vmax=np.concatenate(vmax), elastic=elastic)
    return att, (f"kept {', '.join(said)} while sewn and draped, as GarmentCode's simulator holds them"
                 + (f"; {elastic.note}, and held there from riding up" if elastic is not None else ""))


def top_elastic(garment: Garment, body: Body, v: np.ndarray) -> Elastic | None:
    """The elastic of a held top (v: its vertices) sewn to nothing -- no waistband, no bodice --
    and cut more than ELASTIC_PAST longer round than the body where it is held (its cloth along
    the top, flat, against the hull of the body's section at its height): one ELASTIC_EASE longer
    round than the body there. None: sewn, or cut to fit."""
    if _sewn_top(garment, v):  # (sewn to a waistband or bodice: they hold it)
        return None
    on = np.zeros(garment.n_vertices, dtype=bool)
    on[v] = True
    edges = np.concatenate([np.stack([f, np.roll(f, -1, axis=1)], axis=-1).reshape(-1, 2)
                            for f in (garment.quads, garment.tris) if len(f)])
    edges = np.unique(np.sort(edges[on[edges[:, 0]] & on[edges[:, 1]]], axis=1), axis=0)
    cloth = float(np.linalg.norm(garment.uv[edges[:, 0]] - garment.uv[edges[:, 1]], axis=1).sum())
    girth = _girth_at(body, garment.positions[v])
    if not (girth > 0.0 and cloth > (1.0 + ELASTIC_PAST) * girth):
        return None
    return Elastic(vertices=np.asarray(v, dtype=np.int64), factor=(1.0 + ELASTIC_EASE) * girth / cloth,
                   cloth=cloth, body=girth)


def _sewn_top(garment: Garment, v: np.ndarray) -> bool:
    """Whether most of a labelled top's vertices are sewn to another part (a waistband, a bodice)."""
    return bool(np.isin(v, garment.seams).mean() > 0.5)


def _girth_at(body: Body, p: np.ndarray) -> float:
    """The body's girth (hull of its section) at the median height of the points p, the section
    nearest their middle (the trunk, not an arm beside it); 0 where the plane misses the body."""
    from engine.body.measure import slice_pieces

    pieces = slice_pieces(body.vertices, body.faces, float(np.median(p[:, 1])))
    if not pieces:
        return 0.0
    mid = p[:, [0, 2]].mean(axis=0)
    return float(min(pieces, key=lambda q: float(np.linalg.norm(q.centroid - mid))).hull_perimeter)


def _round_body(body: Body, p: np.ndarray) -> bool:
    """Whether the held edge's middle lies within the body's horizontal extent at its height: a
    waist tie holds on a body, not on the air beside it (a pattern placed away from the body is
    let fall, and said so, rather than hung where it was put)."""
    y = float(p[:, 1].mean())
    near = body.vertices[np.abs(body.vertices[:, 1] - y) < 0.05]
    if not len(near):
        return False
    mid = p[:, [0, 2]].mean(axis=0)
    lo, hi = near[:, [0, 2]].min(axis=0), near[:, [0, 2]].max(axis=0)
    return bool(np.all(mid >= lo) and np.all(mid <= hi))


def welded(att: Attachment | None, vertex_map: np.ndarray) -> Attachment | None:
    """The attachment on the welded cloth (vertex_map: old -> new vertex), each vertex once."""
    if att is None:
        return None
    # (each welded vertex once per plane: a vertex held from both sides keeps both)
    keys = np.c_[vertex_map[att.vertices], np.round(att.normals, 6)]
    _, first = np.unique(keys, axis=0, return_index=True)
    first = np.sort(first)
    return Attachment(vertices=vertex_map[att.vertices[first]].astype(np.int64), points=att.points[first],
                      normals=att.normals[first], tau=att.tau[first],
                      vmax=att.vmax[first])  # (an elastic is in the welded model's springs)


STANDS_OFF = 0.04  # m: a held top whose vertices ended this far from the body (median) stands off it


def stands_off(garment: Garment, body: Body, draped: np.ndarray, vertex_map: np.ndarray | None,
               held: Attachment | None, bvh) -> str | None:
    """A warning where a lower garment's held top ('lower_interface') ended standing off the body:
    its vertices STANDS_OFF or farther from it (median; bvh: the body's MeshBVH). GarmentCode's
    random skirts include tops cut far wider than the waist with no waistband; held at the waist,
    as its simulator holds them, such a top stands off the body as a tube (a real one would need a
    tie, elastic or a band). None: none held, its top sewn to another part (a dress's skirt to its
    bodice), or it lies on the body (a ruffled waistband's hull is wider round than the waist, and
    it lies on it: judged by distance, not by girth)."""
    from engine.body.measure import hull_perimeter

    v = garment.labelled.get("lower_interface")
    if held is None or v is None or not len(v) or vertex_map is None or not np.isin(v, held.vertices).any():
        return None
    if _sewn_top(garment, v):  # (sewn to a bodice: the dress hangs from its shoulders)
        return None
    p = draped[vertex_map[v]]
    off = float(np.median(bvh.signed_distance(p, max_distance=4 * STANDS_OFF)))
    if off < STANDS_OFF:
        return None
    girth = _girth_at(body, p)
    round_ = (f"is {100 * hull_perimeter(p[:, [0, 2]]):.0f} cm round where the body is {100 * girth:.0f} cm round, "
              if girth > 0.0 else "")
    return (f"the garment's top ('lower_interface') {round_}{100 * off:.0f} cm off the body: held there as "
            "GarmentCode's simulator holds it, it stands off the body (a real one would need a waistband, a tie "
            "or elastic; look at the pictures)")
