"""A cloth solver's scratch arrays, made once for a model and a step configuration (the kernels
allocate nothing per step)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.cloth.config import PRECISIONS, StepConfig
from engine.cloth.model import FLEXION, SHEAR, ClothModel, SpringRuns, spring_runs


@dataclass(eq=False)
class StepBuffers:
    """N vertices, S springs, M = N + Q + T checked points (vertices, quad midpoints, triangle
    centroids)."""

    # the force pass (kernels_forces.eval_forces_and_integrate)
    runs: SpringRuns  # the springs in the force pass's order
    sprops: np.ndarray  # (4, S) rest, stiffness, damping, listing length, in runs order and the pass's precision
    one: np.floating  # 1 and 1e-30 in that precision
    tiny: np.floating
    f: np.ndarray  # (N, 3) the last forces kept (FireRelaxer)
    f_out: np.ndarray  # where the pass writes them: f, or (0, 3) when not kept
    soa: np.ndarray  # (9, N) float64 positions, velocities, forces by component (also the guard's)
    fsoa: np.ndarray  # (9, N) the same in the pass's precision (soa itself in double)
    f_slow: np.ndarray  # (3, N) the slow group's forces as last evaluated
    run_tmp: np.ndarray  # (3, longest run)
    lengths: np.ndarray  # (S,) spring lengths, runs order
    listed: np.ndarray  # (S rounded up to 8,) uint8 marks of long springs; listed_words: as uint64
    listed_words: np.ndarray
    geo_s: np.ndarray  # (S, 4) the marked springs' direction and excess, by model index
    # the springs past the strain limit, listed by the force pass (model order)
    work: np.ndarray  # (S,) int32 their model indices
    geo: np.ndarray  # (S, 4) direction and excess
    ends: np.ndarray  # (S, 2) int32
    near: np.ndarray  # (S,) int32 places in the list of those near the guard's length
    # contacts of the last collision check
    contact: np.ndarray  # (N,) bool
    contact_n: np.ndarray  # (N, 3) the body's normal there
    body_v: np.ndarray  # (N, 3) the body's velocity there
    # the checked points
    points: np.ndarray  # (M, 3) where the check looks (predicted)
    pre_points: np.ndarray  # (M, 3) the next check's, predicted (a prefetching collider)
    faces: tuple[np.ndarray, np.ndarray]  # (quads, tris) whose points the solver makes (none: the collider does)
    hit_buf: np.ndarray  # (M,) int32, kernels_contact.contact_rounds' work buffers
    touched_buf: np.ndarray  # (N,) int32
    # the strain guard
    x_guard: np.ndarray  # (N, 3) positions before the guard moved them
    saved: np.ndarray  # (N,) uint8 which points those are, and their list
    saved_list: np.ndarray  # (N,) int32
    guard_work: np.ndarray  # (S,) int32 the springs projected (late guard: apart from `work`)
    guard_lim2: np.ndarray  # (S,) squared lengths past which the guard looks at a spring (run order)
    late_lim2: np.ndarray  # (S,) the same by model index (late guard)

    @classmethod
    def make(cls, model: ClothModel, config: StepConfig, collider_makes_faces: bool) -> "StepBuffers":
        n, s = model.n, len(model.springs)
        m = n + len(model.quads) + len(model.tris)
        runs = model.runs
        if config.hold_shear and (model.kind == SHEAR).any():
            runs = spring_runs(model.springs, slow=model.kind == FLEXION, held=model.kind == SHEAR)
        dtype = PRECISIONS[config.precision]
        soa = np.zeros((9, n))
        listed = np.zeros(-(-s // 8) * 8, dtype=np.uint8)
        f = np.zeros((n, 3))
        threshold = model.fabric.strain_threshold + (config.strain_guard or 0.0)
        faces = (model.quads[:0], model.tris[:0]) if collider_makes_faces else (model.quads, model.tris)
        return cls(runs=runs, sprops=spring_props(model, runs, dtype), one=dtype(1.0), tiny=dtype(1e-30),
                   f=f, f_out=f if config.keep_forces else np.zeros((0, 3)), soa=soa,
                   fsoa=soa if dtype == np.float64 else np.zeros((9, n), dtype), f_slow=np.zeros((3, n), dtype),
                   run_tmp=np.zeros((3, runs.longest), dtype), lengths=np.zeros(s, dtype), listed=listed,
                   listed_words=listed.view(np.uint64), geo_s=np.zeros((s, 4)),
                   work=np.zeros(s, dtype=np.int32), geo=np.zeros((s, 4)), ends=np.zeros((s, 2), dtype=np.int32),
                   near=np.zeros(s, dtype=np.int32),
                   contact=np.zeros(n, dtype=np.bool_), contact_n=np.zeros((n, 3)), body_v=np.zeros((n, 3)),
                   points=np.zeros((m, 3)), pre_points=np.zeros((m, 3)), faces=faces,
                   hit_buf=np.zeros(m, dtype=np.int32), touched_buf=np.zeros(n, dtype=np.int32),
                   x_guard=np.zeros((n, 3)), saved=np.zeros(n, dtype=np.uint8),
                   saved_list=np.zeros(n, dtype=np.int32), guard_work=np.zeros(s, dtype=np.int32),
                   guard_lim2=np.ascontiguousarray(limits2(model, threshold)[runs.fast.perm]),
                   late_lim2=np.ascontiguousarray(limits2(model, threshold)))

    def restiffen(self, model: ClothModel) -> None:
        """The spring properties of `model` (the same springs, other stiffness)."""
        self.sprops = spring_props(model, self.runs, self.sprops.dtype.type)


def spring_props(model: ClothModel, runs: SpringRuns, dtype) -> np.ndarray:
    """(4, S) rest, stiffness, damping and listing length (inf: not limited) in the force pass's
    order and precision."""
    limit = np.where(model.strain_limited, (1.0 + model.fabric.strain_threshold) * model.limit_rest, np.inf)
    return np.ascontiguousarray(np.stack([model.rest, model.stiffness, model.spring_c, limit])[:, runs.perm],
                                dtype=dtype)


def limits2(model: ClothModel, threshold: float) -> np.ndarray:
    """By model index: a hair below the squared length at which a spring passes `threshold` -- a
    superset of the long ones, whatever the rounding -- and inf for springs the strain limit
    leaves alone."""
    lim = (1.0 + threshold) * model.limit_rest
    return np.where(model.strain_limited, lim * lim * (1.0 - 1e-9), np.inf)
