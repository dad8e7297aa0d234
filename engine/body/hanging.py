"""The arms where they hang free of the torso: below the armpits, apart from the body.

GarmentCode's simulator lets the cloth of lower garments pass through the arms (it labels cloth
by the nearest body part and a leg's cloth ignores the arms' faces): a wide skirt placed round
the hips otherwise catches on a hand hanging beside it while its side seams close. Sewing and
the drape until it first settles do the same here (engine.scene.tryon._arms_passed), and need to
know which of the body is a hanging arm.
"""

from __future__ import annotations

import numpy as np

from engine.body.types import SEGMENTS, Body

CUT_BELOW = 0.02  # m under the armpits where the arms are cut from the torso
REACH = 0.03  # m: a part reaching this close to the cut hangs from it (a scan's floating speck does not)
MIN_SHARE = 0.005  # a hanging part has at least this share of the body's vertices
APART = 0.02  # m: and stays this far from the trunk from APART_BELOW under the armpits down (cloth
APART_BELOW = 0.10  # passed through an arm held closer would be caught between arm and trunk)


def hanging_arms(body: Body, armpit_y: float, whole: bool = False):
    """(N,) bool: the body's vertices on an arm that hangs apart from the trunk, from APART_BELOW
    under armpit_y (world height) down -- the arms by their segment labels, or where the body has
    none, the parts of the mesh below the cut that are not joined to the trunk there -- that stay
    at least APART from the trunk there (an A-pose's arms; not arms held against the torso, hands
    on the hips). None where there is no such arm. whole: (that, the same arms from the cut down,
    the upper arm beside the armpit too)."""
    v, f = body.vertices, np.asarray(body.faces)
    if not np.isfinite(armpit_y) or not len(f):
        return None
    below = v[:, 1] < armpit_y - CUT_BELOW
    if body.segments is not None:
        parts = [(body.segments == SEGMENTS.index(s)) & below for s in ("left_arm", "right_arm")]
    else:
        parts = _apart_below(v, f, below, armpit_y)
    parts = [p for p in parts if p.sum() >= max(3, MIN_SHARE * len(v))]
    if not parts:
        return None
    from scipy.spatial import cKDTree

    trunk = below & ~np.any(parts, axis=0)
    if not trunk.any():
        return None
    tree = cKDTree(v[trunk])
    arm, full = np.zeros(len(v), bool), np.zeros(len(v), bool)
    low = v[:, 1] < armpit_y - APART_BELOW
    for p in parts:
        if (p & low).any() and tree.query(v[p & low], distance_upper_bound=APART)[0].min() >= APART:
            arm |= p & low  # (the upper arm beside the armpit stays: a top's side is sewn there)
            full |= p
    if not arm.any():
        return None
    return (arm, full) if whole else arm


def _apart_below(v: np.ndarray, f: np.ndarray, below: np.ndarray, armpit_y: float) -> list[np.ndarray]:
    """The parts of the mesh below the cut, less the largest (the trunk), that reach up to the cut."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    keep = below[f].all(axis=1)
    e = np.concatenate([f[keep][:, [0, 1]], f[keep][:, [1, 2]]])
    n = len(v)
    n_comp, lab = connected_components(coo_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])), shape=(n, n)),
                                       directed=False)
    lab = np.where(below, lab, -1)
    sizes = np.bincount(lab[below], minlength=n_comp)
    if not sizes.any():
        return []
    trunk = int(np.argmax(sizes))
    out = []
    for c in np.flatnonzero(sizes):
        part = lab == c
        if c != trunk and v[part, 1].max() >= armpit_y - CUT_BELOW - REACH:
            out.append(part)
    return out
