"""GarmentCode's attachments: its simulator holds some labelled edges of a pattern in place for
its first frames while the panels are sewn -- the top of a lower garment ("lower_interface") at
the waist, a strapless top ("strapless_top") under the arms, a collar's ends ("right_collar",
"left_collar") beside the neck. Here the same: the labelled edges' vertices held on those planes
(engine.cloth.welds.hold_on_planes) while the garment is sewn and draped (GarmentCode's data set
holds them for its first 400 frames, about its whole simulation); the body's own levels are
measured (engine.body.measure)."""

from __future__ import annotations

import numpy as np

from engine.body.types import Body
from engine.cloth.config import Attachment
from engine.errors import TryonError
from engine.garment.garment import Garment

# how firmly each label is held: (s to bring a vertex back to its plane, at most m/s) -- a
# waistband and a strapless top firmly (they carry the garment), a neckline gently toward the neck
HOLD = {"lower_interface": (0.05, 1.0), "strapless_top": (0.05, 1.0), "right_collar": (0.5, 0.1),
        "left_collar": (0.5, 0.1)}
NECK_INSIDE = 0.01  # m: a collar's ends held this far inside the neck's half width (GarmentCode: 1 cm)


def attachment(garment: Garment, body: Body) -> tuple[Attachment | None, str | None]:
    """The attachment of the garment's labelled edges on this body, and what the report says of
    it (None, None: no labelled edge, or the body could not be measured)."""
    from engine.body.measure import measure
    from engine.pattern.catalogue import neck_half_width

    planes = {}
    try:
        m = measure(body)
    except TryonError:
        return None, None
    if "lower_interface" in garment.labelled and np.isfinite(m.waist_height):
        planes["lower_interface"] = ((0.0, m.waist_height, 0.0), (0.0, 1.0, 0.0), "at the waist")
    if "strapless_top" in garment.labelled and np.isfinite(m.armpit_height):
        planes["strapless_top"] = ((0.0, m.armpit_height, 0.0), (0.0, 1.0, 0.0), "under the arms")
    if {"right_collar", "left_collar"} & set(garment.labelled) and np.isfinite(m.shoulder_height):
        half = neck_half_width(body, m.shoulder_height + 0.05) - NECK_INSIDE
        if half > 0.02:
            planes["right_collar"] = ((-half, 0.0, 0.0), (1.0, 0.0, 0.0), "beside the neck")
            planes["left_collar"] = ((half, 0.0, 0.0), (-1.0, 0.0, 0.0), "beside the neck")
    idx, points, normals, tau, vmax, said = [], [], [], [], [], []
    for label, (point, normal, where) in planes.items():
        v = garment.labelled.get(label)
        if v is None or not len(v):
            continue
        idx.append(v)
        points.append(np.tile(point, (len(v), 1)))
        normals.append(np.tile(normal, (len(v), 1)))
        tau.append(np.full(len(v), HOLD[label][0]))
        vmax.append(np.full(len(v), HOLD[label][1]))
        said.append(f"'{label}' {where}")
    if not idx:
        return None, None
    att = Attachment(vertices=np.concatenate(idx).astype(np.int64), points=np.concatenate(points),
                     normals=np.concatenate(normals), tau=np.concatenate(tau), vmax=np.concatenate(vmax))
    return att, f"held {', '.join(said)} while sewn and draped, as GarmentCode's simulator holds them"


def welded(att: Attachment | None, vertex_map: np.ndarray) -> Attachment | None:
    """The attachment on the welded cloth (vertex_map: old -> new vertex), each vertex once."""
    if att is None:
        return None
    new, first = np.unique(vertex_map[att.vertices], return_index=True)
    return Attachment(vertices=new.astype(np.int64), points=att.points[first], normals=att.normals[first],
                      tau=att.tau[first], vmax=att.vmax[first])
