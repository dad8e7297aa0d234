"""The static part of a cloth (Warp/Newton's Model): masses, springs, faces, seams, time step.
The changing part is ClothState (positions, velocities).

Springs (seed 003 §3): structural along every mesh edge, shear across every quad's diagonals,
flexion between grid vertices two apart (and across the edges of the triangles in the band
along the outline). Rest lengths come from the flat pattern, so the cloth is unstretched when
it lies flat. Stiffness from the fabric (engine.cloth.fabrics):
  structural: k = stretch * stiffness_scale   (a grid spring carries a strip as wide as long)
  shear:      k = shear * stiffness_scale     (diagonal springs: k = G for small shear angles)
  flexion:    k = bending / h^2               (resists the in-plane compression folds make)
Time step: eq. 4, dt <= 0.4 pi sqrt(m / K), with K the stiffness a point feels: the sum over
its springs (for a point on one spring this is the paper's K; on a grid a point hangs on ~8
springs, and the single-spring reading of eq. 4 measured unstable here -- see
tests/test_cloth.py).
Eq. 4 assumes equal point masses; lumped masses along a clipped outline can be much smaller
(sliver triangles), so every point gets at least MASS_FLOOR x the median mass -- a fraction of the
garment's weight -- rather than letting slivers dictate the step. Then the points whose m / K lies
below the MASS_SCALE_PERCENTILE-th percentile get the mass that brings them up to it (selective
mass scaling, as explicit structural codes do; docs/tuning.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from engine.cloth.fabrics import Fabric, get_fabric
from engine.errors import InputError

STRUCTURAL, SHEAR, FLEXION = 0, 1, 2
EQ4_FACTOR = 0.4 * np.pi
MASS_FLOOR = 0.5
MASS_SCALE_PERCENTILE = 5.0
DAMPING_CAP = 0.25  # a spring's damping is at most this x m / (dt degree): see _assemble
EASE = 0.10  # stitched edges differing by at most this fraction are eased together, more are gathered


@dataclass(frozen=True)
class ClothParams:
    """The cloth's physical parameters that are not fabric properties (docs/tuning.md)."""

    stiffness_scale: float = 0.03  # measured stretch and shear stiffness x this (see fabrics.py) ...
    # ... but each fabric's at least as stiff for its weight as this fabric's (None: no floor): at 0.03
    # a knit's own springs (jersey 42 N/m, stretch_knit 18) let it sag under its own weight toward its
    # threshold (a gown 12 % longer than cut), where a real knit stretches well under 1 %
    sag_as: str | None = "cotton"
    damping: float = 0.02  # viscous damping per unit mass, 1/s (times mass: the seeds' C_vd, N.s/m)
    spring_damping: float = 0.3  # damping along each spring, a fraction of its critical damping 2 sqrt(k m)
    reflection: float = 0.0  # C_refl of eq. 12 (0: the cloth does not bounce off the body)
    tolerance: float = 0.003  # m: the collision tolerance band (seed 003 §5.4: 5 mm; docs/tuning.md)


@dataclass
class ClothModel:
    """Arrays (N vertices, S springs): mass (N,), inv_mass (N,), springs (S, 2) int32,
    rest (S,), stiffness (S,), kind (S,) int8; CSR vertex->spring adjacency adj_ptr (N+1,),
    adj_other (2S,), adj_spring (2S,); faces quads (Q, 4) / tris (T, 3); seams (P, 2)."""

    mass: np.ndarray
    inv_mass: np.ndarray
    springs: np.ndarray
    rest: np.ndarray
    stiffness: np.ndarray
    kind: np.ndarray
    spring_c: np.ndarray  # (S,) N.s/m, damping along each spring
    adj_ptr: np.ndarray
    adj_other: np.ndarray
    adj_spring: np.ndarray
    quads: np.ndarray
    tris: np.ndarray
    seams: np.ndarray
    fabric: Fabric
    params: ClothParams
    dt_bound: float
    edge_length: float
    # (S,) |sin 2 phi| of each shear spring's direction phi on the flat pattern against the mesh's
    # grid (the yarns): 1 for a quad's diagonal; 0 for the other springs; how far shear can
    # lengthen it (limit_rest)
    bias: np.ndarray | None = None
    # (S,) how much longer than its rest a spring may grow before the strain limit holds it, relative
    # to the model's fabric: (1 + its own fabric's threshold) / (1 + the model's) for the springs of a
    # part sewn from another fabric (build_model's panel_fabrics); None: every spring the model's
    allow: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.mass)

    @cached_property
    def strain_limited(self) -> np.ndarray:
        """(S,) bool: the springs the strain limit applies to (flexion springs shorten and
        lengthen with folds)."""
        return self.kind != FLEXION

    @cached_property
    def limit_rest(self) -> np.ndarray:
        """(S,) the lengths the strain limit and the reported strain measure each spring from:
        the longest it can be with its yarns unstretched, the weave sheared up to where it locks
        (Fabric.shear_lock; engine.cloth.fabrics): a quad's diagonal at phi to the yarns lengthens
        by sqrt(1 + |sin 2 phi| sin angle) under a shear of that angle (22.5 % at 30 degrees);
        every other spring (bias 0) from its rest length. Strain past it stretches yarns. A part in
        another fabric (allow) is measured from its rest times allow: the strain limit holds it at its
        own fabric's threshold, and a strain read from here is the same share of its own limit."""
        base = self.rest
        if self.bias is not None:
            lock = np.sin(np.radians(self.fabric.shear_lock))
            base = np.where(self.kind == FLEXION, self.rest, self.rest * np.sqrt(1.0 + self.bias * lock))
        if self.allow is not None:
            base = np.where(self.kind == FLEXION, base, base * self.allow)
        return base

    @cached_property
    def runs(self) -> "SpringRuns":
        """The springs in the order of the force pass (see SpringRuns; the flexion springs as its
        slow group), made once per model."""
        return spring_runs(self.springs, slow=self.kind == FLEXION)


MIN_RUN = 8  # shortest run of springs the force pass takes as one vector loop (4 doubles a
# vector; a run's own cost, ~20 ns, outweighs the gain below this)


@dataclass(frozen=True, eq=False)
class SpringRuns:
    """The springs ordered for the force pass (engine.cloth.kernels_forces.eval_forces_and_integrate):
    runs first -- springs (a0 + t, b0 + t) for t < L, L >= MIN_RUN, as a grid row and the next
    row (or the same row shifted) give them -- then the rest.
    perm (S,) int64: the model's index of each spring in this order; springs (S, 2) int32 =
    model springs[perm], ends as in the model; runs (R, 4) int64: (first position in this order,
    a0, b0, L); n_run: the springs in runs (they come first).
    With a slow group (spring_runs' `slow`, the force pass evaluates it every few steps only):
    the fast springs come first, ordered as above (runs[:r_fast], n_run of them in runs, n_fast
    in all), then the slow ones, ordered the same way (runs[r_fast:], their n_run_slow springs in
    runs from position n_fast on, then the rest).
    With held springs (spring_runs' `held`: fast springs whose forces the force pass evaluates
    with the slow group, while still listing them every step): the fast group's runs are its
    other springs' runs (runs[:r_held]) and then the held ones' (runs[r_held:r_fast]), the
    springs of both outside runs after them (the force pass evaluates those every step)."""

    perm: np.ndarray
    springs: np.ndarray
    runs: np.ndarray
    n_run: int
    r_fast: int = -1
    n_fast: int = -1
    n_run_slow: int = 0
    r_held: int = -1

    def __post_init__(self):
        if self.r_fast < 0:  # no slow group
            object.__setattr__(self, "r_fast", len(self.runs))
            object.__setattr__(self, "n_fast", len(self.perm))
        if self.r_held < 0:  # no held springs
            object.__setattr__(self, "r_held", self.r_fast)

    @property
    def longest(self) -> int:
        return int(self.runs[:, 3].max(initial=1))

    @cached_property
    def fast(self) -> "SpringRuns":
        """The fast group alone (all springs when there is no slow group)."""
        if self.n_fast == len(self.perm):
            return self
        return SpringRuns(perm=self.perm[:self.n_fast], springs=self.springs[:self.n_fast],
                          runs=self.runs[:self.r_fast], n_run=self.n_run)


def _held_runs(springs: np.ndarray, held: np.ndarray, min_run: int) -> SpringRuns:
    """The runs of the springs not held, then those of the held ones, then the springs of both
    outside runs (SpringRuns' held layout)."""
    own_i, held_i = np.flatnonzero(~held), np.flatnonzero(held)
    o, h = spring_runs(springs[own_i], min_run), spring_runs(springs[held_i], min_run)
    hr = h.runs.copy()
    hr[:, 0] += o.n_run
    perm = np.concatenate([own_i[o.perm[:o.n_run]], held_i[h.perm[:h.n_run]],
                           own_i[o.perm[o.n_run:]], held_i[h.perm[h.n_run:]]]).astype(np.int64)
    return SpringRuns(perm=perm, springs=springs[perm].astype(np.int32), runs=np.concatenate([o.runs, hr]),
                      n_run=o.n_run + h.n_run, r_held=len(o.runs))


def spring_runs(springs: np.ndarray, min_run: int = MIN_RUN, slow: np.ndarray | None = None,
                held: np.ndarray | None = None) -> SpringRuns:
    """Find the runs: springs sorted by end-to-end offset b - a, then by a; a run is a stretch of
    that order where a goes up by one each spring. slow: (S,) bool, the springs of the slow group
    (see SpringRuns), ordered the same way after the others. held: (S,) bool, fast springs whose
    forces go with the slow group's (SpringRuns; the walk's shear springs)."""
    held = held if held is not None and held.any() else None
    if held is not None and slow is not None and (slow & held).any():
        raise ValueError("spring_runs: a held spring is a fast one; it cannot be slow too")
    if slow is not None and slow.any():
        fast_i, slow_i = np.flatnonzero(~slow), np.flatnonzero(slow)
        f = spring_runs(springs[fast_i], min_run, held=None if held is None else held[fast_i])
        w = spring_runs(springs[slow_i], min_run)
        perm = np.concatenate([fast_i[f.perm], slow_i[w.perm]]).astype(np.int64)
        wr = w.runs.copy()
        wr[:, 0] += len(fast_i)
        return SpringRuns(perm=perm, springs=springs[perm].astype(np.int32), runs=np.concatenate([f.runs, wr]),
                          n_run=f.n_run, r_fast=len(f.runs), n_fast=len(fast_i), n_run_slow=w.n_run,
                          r_held=f.r_held)
    if held is not None:
        return _held_runs(springs, held, min_run)
    s = springs.astype(np.int64).reshape(-1, 2)
    d = s[:, 1] - s[:, 0]
    order = np.lexsort((s[:, 0], d))
    a, dd = s[order, 0], d[order]
    brk = np.ones(len(order), dtype=np.bool_)
    brk[1:] = (dd[1:] != dd[:-1]) | (a[1:] != a[:-1] + 1)
    starts = np.flatnonzero(brk)
    lens = np.diff(np.r_[starts, len(order)])
    keep = lens >= min_run
    st, ln = starts[keep], lens[keep]
    first = np.cumsum(ln) - ln  # each run's first position in the new order
    pos = np.repeat(st - first, ln) + np.arange(ln.sum())  # the sorted positions of the runs' springs
    in_run = np.zeros(len(order), dtype=np.bool_)
    in_run[pos] = True
    perm = np.concatenate([order[pos], order[~in_run]]).astype(np.int64)
    runs = np.stack([first, s[order[st], 0], s[order[st], 1], ln], axis=1).astype(np.int64)
    return SpringRuns(perm=perm, springs=springs[perm].astype(np.int32), runs=runs, n_run=int(ln.sum()))


@dataclass
class ClothState:
    x: np.ndarray  # (N, 3) float64 positions
    v: np.ndarray  # (N, 3) float64 velocities

    def copy(self) -> "ClothState":
        return ClothState(self.x.copy(), self.v.copy())


def _pair_keys(pairs: np.ndarray) -> np.ndarray:
    """(P,) int64 keys of (P, 2) pairs of indices >= 0, in the pairs' lexicographic order: np.unique
    of the keys is np.unique(pairs, axis=0) (same order, same first indices), without its slow
    row-wise sort."""
    p = pairs.astype(np.int64)
    return p[:, 0] * (int(p.max(initial=0)) + 1) + p[:, 1]


def _unique_pairs(pairs: np.ndarray) -> np.ndarray:
    p = np.sort(pairs, axis=1)
    p = p[p[:, 0] != p[:, 1]]
    _, first = np.unique(_pair_keys(p), return_index=True)
    return p[first]


def _pairs_in(pairs: np.ndarray, among: np.ndarray) -> np.ndarray:
    """(P,) bool: which rows of pairs (P, 2) are rows of among (M, 2), both as given (sort the
    ends first for unordered pairs)."""
    a, b = pairs.astype(np.int64), among.astype(np.int64)
    n = int(max(a.max(initial=0), b.max(initial=0))) + 1
    return np.isin(a[:, 0] * n + a[:, 1], b[:, 0] * n + b[:, 1])


def build_springs(uv: np.ndarray, panel: np.ndarray, lattice: np.ndarray, quads: np.ndarray,
                  tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(S, 2) int32 springs and (S,) int8 kinds from the flat mesh."""
    edges = [quads[:, [0, 1]], quads[:, [1, 2]], quads[:, [2, 3]], quads[:, [3, 0]],
             tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]
    structural = _unique_pairs(np.concatenate(edges))
    shear = _unique_pairs(np.concatenate([quads[:, [0, 2]], quads[:, [1, 3]]]))
    # flexion on the grid: (i, j) - (i + 2, j) and (i, j) - (i, j + 2), same panel, middle present
    on = np.flatnonzero(lattice[:, 0] >= 0)
    flex = []
    if len(on):
        lat = lattice[on].astype(np.int64)
        lo = lat.min(axis=0)
        span = lat.max(axis=0) - lo + 3  # room for i + 2, j + 2

        def code(pp, ij):
            return (pp * span[0] + (ij[:, 0] - lo[0])) * span[1] + (ij[:, 1] - lo[1])

        pan = panel[on].astype(np.int64)
        keys = code(pan, lat)
        order = np.argsort(keys)
        sk = keys[order]

        def find(c):  # vertex with code c, or -1
            k = np.minimum(np.searchsorted(sk, c), len(sk) - 1)
            return np.where(sk[k] == c, on[order[k]], -1)

        for d in (np.array([1, 0]), np.array([0, 1])):
            mid, far = find(code(pan, lat + d)), find(code(pan, lat + 2 * d))
            ok = (mid >= 0) & (far >= 0)
            flex += list(zip(on[ok].tolist(), far[ok].tolist()))
    # flexion across the band's triangle edges: the two vertices opposite a shared edge
    if len(tris):
        te = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
        opp = np.concatenate([tris[:, 2], tris[:, 0], tris[:, 1]])
        k = np.sort(te, axis=1)
        order = np.lexsort((k[:, 1], k[:, 0]))
        ks, os_ = k[order], opp[order]
        same = np.all(ks[1:] == ks[:-1], axis=1)
        idx = np.flatnonzero(same)
        flex += list(zip(os_[idx].tolist(), os_[idx + 1].tolist()))
    flex = _unique_pairs(np.asarray(flex, dtype=np.int64).reshape(-1, 2)) if flex else np.zeros((0, 2), np.int64)
    # a structural/shear pair is not also a flexion spring
    if len(flex):
        flex = flex[~_pairs_in(flex, np.concatenate([structural, shear]))].reshape(-1, 2)
    springs = np.concatenate([structural, shear, flex]).astype(np.int32)
    kind = np.concatenate([np.full(len(structural), STRUCTURAL), np.full(len(shear), SHEAR),
                           np.full(len(flex), FLEXION)]).astype(np.int8)
    return springs, kind


def lumped_mass(uv: np.ndarray, quads: np.ndarray, tris: np.ndarray, density: float) -> np.ndarray:
    """(N,) kg: each face's mass shared equally by its corners (areas from the flat pattern)."""
    m = np.zeros(len(uv))
    if len(quads):
        a = uv[quads]
        d1, d2 = a[:, 2] - a[:, 0], a[:, 3] - a[:, 1]
        area = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
        np.add.at(m, quads.ravel(), np.repeat(area / 4.0, 4))
    if len(tris):
        a = uv[tris]
        d1, d2 = a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]
        area = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
        np.add.at(m, tris.ravel(), np.repeat(area / 3.0, 3))
    return m * density


def csr_adjacency(n: int, springs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a, b = springs[:, 0], springs[:, 1]
    ends = np.concatenate([a, b])
    other = np.concatenate([b, a])
    sid = np.concatenate([np.arange(len(springs)), np.arange(len(springs))])
    order = np.argsort(ends, kind="stable")
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.add.at(ptr, ends + 1, 1)
    return np.cumsum(ptr), other[order].astype(np.int32), sid[order].astype(np.int32)


def build_model(uv: np.ndarray, panel: np.ndarray, lattice: np.ndarray, quads: np.ndarray,
                tris: np.ndarray, seams: np.ndarray, fabric: Fabric, h: float,
                params: ClothParams | None = None, panel_fabrics: dict[int, Fabric] | None = None) -> ClothModel:
    """Build the model from the flat (unsewn) mesh; weld_model() merges sewn vertices later.
    panel_fabrics: panel index -> the fabric that panel is sewn from, where not `fabric` (a cuff or
    band in a knit on a cotton shirt): its springs take that fabric's stiffness, its cloth that
    fabric's weight, and the strain limit holds it at that fabric's threshold (ClothModel.allow)."""
    params = params or ClothParams()
    if params.stiffness_scale <= 0 or not np.isfinite(params.stiffness_scale):
        raise InputError(f"stiffness scale must be positive, got {params.stiffness_scale}")
    springs, kind = build_springs(uv, panel, lattice, quads, tris)
    a, b = springs[:, 0], springs[:, 1]
    rest = np.linalg.norm(uv[a] - uv[b], axis=1)
    if np.any(rest <= 1e-6):
        raise InputError("the cloth mesh has coincident vertices (a spring of zero rest length)")
    k = _stiffness(kind, uv[b] - uv[a], fabric, params, h)
    mass = lumped_mass(uv, quads, tris, fabric.density)
    allow = None
    if panel_fabrics:
        allow = np.ones(len(springs))
        for p, other in panel_fabrics.items():
            on_v = panel == p
            on = on_v[a] & on_v[b]  # (a spring lies in one panel until the seams are welded)
            k = np.where(on, _stiffness(kind, uv[b] - uv[a], other, params, h), k)
            allow[on] = (1.0 + other.strain_threshold) / (1.0 + fabric.strain_threshold)
            mass = np.where(on_v, mass * (other.density / fabric.density), mass)
    k = np.where(_gathered(springs, rest, seams), 0.0, k)
    if np.any(mass <= 0):
        raise InputError("the cloth mesh has vertices that belong to no face")
    mass = np.maximum(mass, MASS_FLOOR * np.median(mass))
    # only a quad's diagonals: its edges are yarns that hold the threshold; a border triangle's
    # slanted edge has no yarn beside it, and lengthening it would let the yarns stretch unseen
    d = uv[b] - uv[a]
    bias = np.where(kind == SHEAR, np.abs(2.0 * d[:, 0] * d[:, 1]) / (rest * rest), 0.0)
    return _biased(_assemble(mass, springs, rest, k, kind, quads, tris, seams, fabric, params, h), bias, allow)


def _gathered(springs: np.ndarray, rest: np.ndarray, seams: np.ndarray) -> np.ndarray:
    """(S,) bool: the springs along the longer edge of a gathered seam -- both ends sewn to the
    ends of a spring more than EASE shorter. Cloth gathered into a shorter edge folds; such a
    spring pushing back at its full rest length held a cuff 80-93 % stretched round a bishop
    sleeve's 57 cm end gathered into its 16 cm (GarmentCode's mean_female 89_008), so it carries
    no force until the seam is welded (weld_model then keeps the short edge's spring)."""
    if not len(seams) or not len(springs):
        return np.zeros(len(springs), bool)
    n = int(max(springs.max(), seams.max())) + 1
    partner = np.full(n, -1, dtype=np.int64)
    partner[seams[:, 0]], partner[seams[:, 1]] = seams[:, 1], seams[:, 0]
    pa, pb = partner[springs[:, 0]], partner[springs[:, 1]]
    both = (pa >= 0) & (pb >= 0) & (pa != pb)
    lo, hi = np.sort(springs, axis=1).astype(np.int64).T
    keys = lo * n + hi
    order = np.argsort(keys)
    want = np.minimum(pa, pb) * n + np.maximum(pa, pb)
    at = np.clip(np.searchsorted(keys[order], want), 0, len(keys) - 1)
    found = both & (keys[order][at] == want)
    other_rest = np.where(found, rest[order][at], np.inf)
    return found & (rest > (1.0 + EASE) * other_rest)


def _stiffness(kind: np.ndarray, d: np.ndarray, fabric: Fabric, params: ClothParams, h: float) -> np.ndarray:
    """spring_stiffness of springs along d (their rest vectors in the panel's frame), for a fabric
    that is soft crosswise only (Fabric.crosswise: a rib) -- crosswise, along the panel's x (round
    the limb or waist: GarmentCode draws a band or cuff so, the DXF reader turns a piece's grain
    line vertical), and on the bias at its own springs; lengthwise, no softer for its weight than
    ClothParams.sag_as. At the floor crosswise too, a rib cuff 17 cm round pushed back harder than
    cotton and its seams stalled 4-6 cm open round a forearm it fits at 37 % (f_smpl 97_010)."""
    floor = spring_stiffness(kind, fabric, params, h)
    if not fabric.crosswise or params.sag_as is None:
        return floor
    own = spring_stiffness(kind, fabric, replace(params, sag_as=None), h)
    return np.where((kind == STRUCTURAL) & (np.abs(d[:, 1]) > np.abs(d[:, 0])), floor, own)


def spring_stiffness(kind: np.ndarray, fabric: Fabric, params: ClothParams, h: float) -> np.ndarray:
    stretch, shear = fabric.stretch, fabric.shear
    if params.sag_as is not None:  # (ClothParams.sag_as: per unit weight, no softer than that fabric)
        ref = get_fabric(params.sag_as)
        stretch = max(stretch, ref.stretch * fabric.density / ref.density)
        shear = max(shear, ref.shear * fabric.density / ref.density)
    return np.where(kind == STRUCTURAL, stretch * params.stiffness_scale,
                    np.where(kind == SHEAR, shear * params.stiffness_scale, fabric.bending / (h * h)))


def _assemble(mass, springs, rest, k, kind, quads, tris, seams, fabric, params, h,
              damping_cap: float = DAMPING_CAP) -> ClothModel:
    a, b = springs[:, 0], springs[:, 1]
    k_point = np.maximum(np.bincount(a, k, len(mass)) + np.bincount(b, k, len(mass)), 1e-12)
    # selective mass scaling: the points whose m / K is below the MASS_SCALE_PERCENTILE-th
    # percentile get the mass that brings them up to it, so a few light points on stiff spring
    # stars do not set everyone's step
    mass = np.maximum(mass, np.percentile(mass / k_point, MASS_SCALE_PERCENTILE) * k_point)
    dt_bound = float(EQ4_FACTOR * np.sqrt(np.min(mass / k_point)))
    ptr, other, sid = csr_adjacency(len(mass), springs)
    if not (0.0 <= params.spring_damping <= 1.0):
        raise InputError(f"spring damping must be between 0 and 1 (a fraction of critical), got {params.spring_damping}")
    m_ab = np.minimum(mass[a], mass[b])
    c = params.spring_damping * 2.0 * np.sqrt(k * m_ab)
    # explicit stability of the damping term at the eq. 4 step: the relative velocity of a
    # point against its neighbours may lose at most half of itself per step (damping_cap 0.25;
    # the walk's softer springs take 0.5: with_stiffness)
    degree = np.bincount(a, minlength=len(mass)) + np.bincount(b, minlength=len(mass))
    c_max = damping_cap * m_ab / (dt_bound * np.maximum(degree[a], degree[b]))
    c = np.minimum(c, c_max)
    return ClothModel(mass=mass, inv_mass=1.0 / mass, springs=springs, rest=rest, stiffness=k, kind=kind,
                      spring_c=c,
                      adj_ptr=ptr, adj_other=other, adj_spring=sid, quads=quads, tris=tris,
                      seams=seams, fabric=fabric, params=params, dt_bound=dt_bound, edge_length=h)


def spring_strains(model: ClothModel, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((L, 2) springs, (L,) strains) of the strain-limited (structural and shear) springs at
    positions x, measured as the strain limit measures them (from limit_rest)."""
    limited = model.kind != FLEXION
    s = model.springs[limited]
    return s, np.linalg.norm(x[s[:, 1]] - x[s[:, 0]], axis=1) / model.limit_rest[limited] - 1.0


def _biased(model: ClothModel, bias: np.ndarray | None, allow: np.ndarray | None = None) -> ClothModel:
    """The model with its springs' bias and allowance (ClothModel.bias, .allow), set before
    limit_rest is first read."""
    model.bias, model.allow = bias, allow
    return model


def with_elastic(model: ClothModel, vertices: np.ndarray, factor: float) -> ClothModel:
    """The model with an edge gathered onto an elastic: the springs between two of `vertices`
    (the edge's own run) `factor` x as long at rest, so the cloth along it gathers as the elastic
    pulls it in, and still measured by the strain limit (and the reported strain) from their full
    length (ClothModel.allow): an elastic stretched back to the cloth's own length is not the cloth
    stretched; past it, it is."""
    if not (0.0 < factor <= 1.0):
        raise InputError(f"elastic factor {factor}: use 0 .. 1 (the elastic's length / the cloth's)")
    on = np.zeros(model.n, dtype=bool)
    on[vertices] = True
    edge = on[model.springs[:, 0]] & on[model.springs[:, 1]]
    allow = model.allow if model.allow is not None else np.ones(len(model.rest))
    return _biased(replace(model, rest=np.where(edge, model.rest * factor, model.rest)), model.bias,
                   np.where(edge & (model.kind != FLEXION), allow / factor, allow))


def with_stiffness(model: ClothModel, factor: float, damping_cap: float | None = None) -> ClothModel:
    """The model with its stretch and shear springs `factor` x as stiff (flexion unchanged: it is
    the fabric's bending), the spring damping and the eq. 4 bound following (dt ~ 1 / sqrt(factor)
    where stretch sets it). Masses, springs and rest lengths stay. damping_cap: the cap on each
    spring's damping, as _assemble's (None: DAMPING_CAP, the drape's)."""
    if not (factor > 0 and np.isfinite(factor)):
        raise InputError(f"stiffness factor must be positive, got {factor}")
    if damping_cap is not None and not (0.0 < damping_cap <= 1.0):
        raise InputError(f"damping cap {damping_cap}: use 0 .. 1")
    if factor == 1.0 and damping_cap is None:
        return model
    k = np.where(model.kind == FLEXION, model.stiffness, model.stiffness * factor)
    params = replace(model.params, stiffness_scale=model.params.stiffness_scale * factor)
    return _biased(_assemble(model.mass, model.springs, model.rest, k, model.kind, model.quads, model.tris,
                             model.seams, model.fabric, params, model.edge_length,
                             DAMPING_CAP if damping_cap is None else damping_cap), model.bias, model.allow)


def seam_flexion(uv: np.ndarray, springs: np.ndarray, kind: np.ndarray, rest: np.ndarray,
                 seams: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flexion springs across sewn seams, on the unsewn vertex indices: for each stitch pair
    (a, b), a's neighbour in its panel most nearly square to the seam, to b's likewise, with the
    rest length of the two panels lying flat across the seam (the sum of the two edges). Without
    them a seam is a free hinge: a skirt sewn flat at its sides kept the 180-degree fold there,
    and the hem turned in along it. Returns ((K, 2) int64 springs, (K,) rest lengths)."""
    on_seam = np.zeros(len(uv), dtype=np.bool_)
    on_seam[seams.ravel()] = True
    st = springs[kind == STRUCTURAL]
    r_st = rest[kind == STRUCTURAL]
    # only seam vertices are asked (below): their springs, in the same order
    touch = on_seam[st[:, 0]] | on_seam[st[:, 1]]
    st, r_st = st[touch], r_st[touch]
    nbrs: dict[int, list[tuple[int, float]]] = {}
    for (i, j), r in zip(st.tolist(), r_st.tolist()):
        nbrs.setdefault(i, []).append((j, r))
        nbrs.setdefault(j, []).append((i, r))

    def across(v: int) -> tuple[int, float] | None:
        around = nbrs.get(v, [])
        inner = [(u, r) for u, r in around if not on_seam[u]]
        along = [u for u, _ in around if on_seam[u]]
        if not inner or not along:
            return None
        t = uv[along[-1]] - uv[along[0]] if len(along) > 1 else uv[along[0]] - uv[v]
        t = t / max(float(np.hypot(*t)), 1e-12)

        def square(ur):
            d = uv[ur[0]] - uv[v]
            return abs(t[0] * d[1] - t[1] * d[0]) / max(float(np.hypot(*d)), 1e-12)

        return max(inner, key=square)

    out, out_rest = [], []
    for a, b in seams.tolist():
        fa, fb = across(a), across(b)
        if fa is not None and fb is not None:
            out.append((fa[0], fb[0]))
            out_rest.append(fa[1] + fb[1])
    return np.asarray(out, dtype=np.int64).reshape(-1, 2), np.asarray(out_rest, dtype=np.float64)


def weld_model(model: ClothModel, vertex_map: np.ndarray, uv: np.ndarray | None = None) -> ClothModel:
    """Merge vertices (sewn seam pairs): vertex_map (N,) -> new index. Springs keep their rest
    lengths from the flat pattern; duplicates (a spring present on both panels) are merged into
    one with the longer rest length (eased), or the shorter where they differ by more than EASE
    (gathered);
    masses add up; seams are gone (they are now shared vertices). With the flat pattern's uv
    (N, 2), flexion springs across the seams are added (seam_flexion)."""
    n_new = int(vertex_map.max()) + 1
    mass = np.zeros(n_new)
    np.add.at(mass, vertex_map, model.mass)
    s = vertex_map[model.springs]
    keep = s[:, 0] != s[:, 1]
    s, rest, k, kind = s[keep], model.rest[keep], model.stiffness[keep], model.kind[keep]
    bias = model.bias[keep] if model.bias is not None else None
    allow = model.allow[keep] if model.allow is not None else None
    key = np.sort(s, axis=1)
    _, first, group = np.unique(_pair_keys(key), return_index=True, return_inverse=True)
    # a spring on both sides of a seam: where the stitched edges differ a little (eased in), the
    # longer rest (the shorter would leave the long side stretched past the strain limit); where
    # they differ more (a gather: the longer edge sewn evenly into the shorter), the shorter, so the
    # seam takes the short edge's length and the long side gathers
    longest = np.full(len(first), -np.inf)
    np.maximum.at(longest, group.ravel(), rest)
    shortest = np.full(len(first), np.inf)
    np.minimum.at(shortest, group.ravel(), rest)
    longest = np.where(longest > (1.0 + EASE) * shortest, shortest, longest)
    stiffest = np.zeros(len(first))  # (a gathered seam's long-edge spring carried none: _gathered)
    np.maximum.at(stiffest, group.ravel(), k)
    order = np.argsort(first)
    first, longest, stiffest = first[order], longest[order], stiffest[order]
    s, rest, k, kind = s[first], longest, np.where(k[first] > 0.0, k[first], stiffest), kind[first]
    if bias is not None:  # a spring on both sides of a seam: the lesser bias (the stricter limit)
        least = np.full(len(first), np.inf)
        np.minimum.at(least, group.ravel(), bias)
        bias = least[order]
    if allow is not None:  # a seam between a knit part and another: the knit's (the seam stretches with it)
        most = np.full(len(first), -np.inf)
        np.maximum.at(most, group.ravel(), allow)
        allow = most[order]
    if uv is not None and len(model.seams):
        fs, fr = seam_flexion(uv, model.springs, model.kind, model.rest, model.seams)
        fs = np.sort(vertex_map[fs], axis=1)
        _, new = np.unique(_pair_keys(fs), return_index=True)  # one per welded pair, none doubling a spring
        new = np.sort(new)
        new = new[(fs[new, 0] != fs[new, 1]) & ~_pairs_in(fs[new], np.sort(s, axis=1))]
        if len(new):
            fk = np.full(len(new), FLEXION, dtype=kind.dtype)
            s = np.concatenate([s, fs[new].astype(s.dtype)])
            rest = np.concatenate([rest, fr[new]])
            kind = np.concatenate([kind, fk])
            k = np.concatenate([k, spring_stiffness(fk, model.fabric, model.params, model.edge_length)])
            bias = np.concatenate([bias, np.zeros(len(new))]) if bias is not None else None
            allow = np.concatenate([allow, np.ones(len(new))]) if allow is not None else None
    return _biased(_assemble(mass, s.astype(np.int32), rest, k, kind,
                             vertex_map[model.quads].astype(np.int32), vertex_map[model.tris].astype(np.int32),
                             np.zeros((0, 2), np.int32), model.fabric, model.params, model.edge_length), bias, allow)
