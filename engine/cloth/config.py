"""How a cloth solver steps: its configuration, fixed when the solver is made, and the controls the
scene sets from step to step (Newton's `control`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.cloth.kernels_strain import VM_MODES
from engine.errors import InputError

PRECISIONS = {"double": np.float64, "single": np.float32}


@dataclass(frozen=True)
class StepConfig:
    """The step's method and tuning (docs/tuning.md has the measurements behind the values)."""

    velocity_mode: str = "average"  # zero (seed 003) | average (seed 000 eq. 5) | directional (eq. 6) | provot
    vm_passes: int = 6  # Gauss-Seidel passes of the strain limit over the over-elongated springs
    contact_rounds: int = 2  # alternations of strain limit and collision response per collision check
    strain_guard: float | None = None  # positions keep springs within the fabric's threshold + this (None: off)
    guard_step: float = 0.0003  # m: the guard shortens a spring by at most this per pass
    recover: float = 0.002  # s: a spring's excess over the strain limit is worked off over this long
    push_time: float = 0.02  # s: a point in the band's inner half (or inside) is moved out over this long
    flexion_every: int = 4  # steps between evaluations of the flexion springs' forces (held in between)
    requery_move: float = 0.001  # m: a checked point asks the collider again once it moved this far ...
    requery_every: int = 8  # ... or after this many steps (in between its answer is carried)
    precision: str = "double"  # the spring forces' arithmetic: double, or single (velocities stay double)
    hold_shear: bool = False  # the shear springs' forces held with the flexion springs' (still limited every step)
    keep_forces: bool = True  # keep each step's forces (FireRelaxer reads them)
    late_guard: bool = False  # guard at the next step's force pass, from its list of long springs
    self_collision: bool = False  # cloth-cloth contact within the cloth (engine.cloth.selfcontact)
    self_thickness: float = 0.003  # m: ... kept between two layers
    self_every: int = 2  # ... checked every this many steps
    # open seam pairs pulled again after the collision response: it sets a vertex in contact to
    # the mean of its faces' responses, which took the pull off seam ends lying on the body
    sew_after_contact: bool = True

    def __post_init__(self):
        if self.velocity_mode not in VM_MODES:
            raise InputError(f"unknown velocity modification '{self.velocity_mode}'; "
                             f"choose one of: {', '.join(VM_MODES)}")
        if self.precision not in PRECISIONS:
            raise InputError(f"precision '{self.precision}': use {' or '.join(PRECISIONS)}")
        for name, lo, hi in (("vm_passes", 1, 100), ("contact_rounds", 1, 16), ("flexion_every", 1, 16),
                             ("requery_every", 1, 1000), ("self_every", 1, 64)):
            k = getattr(self, name)
            if not (isinstance(k, (int, np.integer)) and lo <= k <= hi):
                raise InputError(f"{name} {k}: use a whole number {lo} .. {hi}")
        if self.strain_guard is not None and not (0.0 <= self.strain_guard <= 0.5):
            raise InputError(f"strain_guard {self.strain_guard}: use 0 .. 0.5 (or None: off)")
        for name, hi in (("guard_step", 0.01), ("recover", 1e9), ("push_time", 0.2), ("requery_move", 0.05),
                         ("self_thickness", 0.02)):
            v = getattr(self, name)
            if not (0 < v <= hi):
                raise InputError(f"{name} {v}: use a positive number up to {hi:g}")

    @property
    def mode(self) -> int:
        """The velocity modification's kernel code (engine.cloth.kernels_strain.VM_MODES)."""
        return VM_MODES[self.velocity_mode]


@dataclass(frozen=True, eq=False)
class Sewing:
    """Seams being sewn: each open pair is pulled shut (engine.cloth.welds.pull_seams)."""

    pairs: np.ndarray  # (P, 2) int64 vertex pairs
    welded: np.ndarray  # (P,) bool: pairs already welded (the scene updates it in place)
    tau: float  # s: an open pair is pulled to close its gap in this time ...
    vmax: float  # m/s: ... at most this fast
    # a flat layout: each panel's velocities are damped toward the panel's mean velocity at this
    # rate (1/s), so a panel pulled at its seams moves as a whole instead of folding about its
    # middle (None: not); panel (N,) int64 the panel of each vertex
    panel: np.ndarray | None = None
    panel_damping: float = 0.0
    # pairs whose straight path runs through the body: each end pulled to meet[k] instead (the
    # scene sets both in place; engine.cloth.welds.pull_seams)
    meet: np.ndarray | None = None  # (P, 3) float64
    meet_on: np.ndarray | None = None  # (P,) bool

    def meeting(self) -> tuple[np.ndarray, np.ndarray]:
        if self.meet is None or self.meet_on is None:
            return np.zeros((1, 3)), np.zeros(len(self.pairs), dtype=np.bool_)
        return self.meet, self.meet_on


@dataclass(frozen=True, eq=False)
class Attachment:
    """Vertices kept in front of planes (GarmentCode's attachment: a waistband kept from sliding
    down while it is sewn; engine.cloth.welds.hold_on_planes)."""

    vertices: np.ndarray  # (K,) int64
    points: np.ndarray  # (K, 3) a point of each vertex's plane
    normals: np.ndarray  # (K, 3) unit: the side of the plane the vertex is kept on
    tau: np.ndarray  # (K,) s: a vertex behind its plane is brought back in this time ...
    vmax: np.ndarray  # (K,) m/s: ... at most this fast
    elastic: object = None  # engine.scene.attach.Elastic: the held top gathered onto an elastic, or None


@dataclass
class Control:
    """What the scene sets for the next steps."""

    gravity_scale: float = 1.0  # x g
    damping_scale: float = 1.0  # x the fabric's viscous damping
    friction_scale: float = 1.0  # x the fabric's cloth-body friction
    collide_every: float = 1  # steps between collision checks (a fraction: that many on average)
    sewing: Sewing | None = None  # seams pulled shut (strain recovery and the strain guard wait meanwhile)
    attachment: Attachment | None = None  # vertices held on planes
    floor: float | None = None  # m: the ground's height: cloth rests on it, with friction (None: none)
