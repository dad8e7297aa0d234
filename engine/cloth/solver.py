"""The cloth solver: an explicit mass-spring cloth with velocity modification against
super-elasticity and image-space collision. Its step reads like seed 003's algorithm: forces,
velocities, velocity modification, collision, positions. Model and state are kept apart as in
Warp/Newton: the solver changes a ClothState in place.

    model = build_model(garment.uv, garment.panel, garment.lattice, garment.quads, garment.tris,
                        garment.seams, get_fabric("cotton"), h=0.015)
    state = ClothState(garment.positions.copy(), np.zeros_like(garment.positions))
    solver = ClothSolver(model, collider, StepConfig(strain_guard=0.009))  # dt: the eq. 4 bound
    for _ in range(1000):
        solver.step(state, Control(collide_every=2))
"""

from __future__ import annotations

import time

import numpy as np

from engine.cloth import passes
from engine.cloth.buffers import StepBuffers
from engine.cloth.carry import CarriedAnswers
from engine.cloth.config import Control, StepConfig
from engine.cloth.kernels_integrate import fire_mix, fire_mix_free, kinetic_energy
from engine.cloth.kernels_strain import VM_PROVOT, max_strain
from engine.cloth.model import ClothModel, ClothState
from engine.cloth.passes import Forcing
from engine.cloth.schedule import CheckSchedule
from engine.cloth.selfcontact import SelfContact
from engine.collide.base import Collider
from engine.errors import InputError

GRAVITY = np.array([0.0, -9.81, 0.0])
NO_RECOVERY = 1e9  # s: the recovery time while sewing (sewing stretches cloth by design: none)


class FireRelaxer:
    """FIRE 2.0 (Bitzek et al., Phys. Rev. Lett. 97, 170201, 2006; Guénolé et al., Comput. Mater.
    Sci. 175, 109584, 2020) on the cloth's velocities, for stages that only want the cloth at rest
    (the drape): after each solver step, while the cloth's power P = f.v is positive its velocity
    is turned a fraction alpha toward the force (alpha decays while P stays positive); as soon as
    P turns negative -- the cloth starts swinging back -- the positions go back half that step
    and every velocity is zeroed. Viscous damping instead slows the cloth's slow modes as much as
    its fast ones. The time step stays at the eq. 4 bound; the half step back keeps that stable.
    The power is the whole cloth's but for the vertices in contact with the body, whose velocity
    the contact response changes outside the forces: their f.v swinging about zero at every
    check zeroed the whole cloth, and a part that needed a run-up to fall never got one (a
    circle skirt stood out round the hips as a flat fan; docs/tuning.md, FireRelaxer)."""

    def __init__(self, alpha: float = 0.1, decay: float = 0.99, delay: int = 5):
        self.alpha0, self.decay, self.delay = alpha, decay, delay
        self.alpha, self.run, self.restarts = alpha, 0, 0
        # (N,) bool: vertices left to fall as the solver moves them, outside FIRE's power and its
        # stops (a circle skirt standing out: engine.scene.drape's stand_out), or None
        self.free: np.ndarray | None = None

    def after_step(self, solver: "ClothSolver", state: ClothState) -> None:
        if self.free is not None:
            p = fire_mix_free(solver.f, state.v, state.x, solver.dt, self.alpha, solver.buf.contact, self.free)
        else:
            p = fire_mix(solver.f, state.v, state.x, solver.dt, self.alpha, solver.buf.contact)
        if p > 0.0:
            self.run += 1
            if self.run > self.delay:
                self.alpha *= self.decay
        else:
            self.alpha, self.run = self.alpha0, 0
            self.restarts += 1


class ClothSolver:
    """Steps a ClothState of `model` against `collider` (None: no body) at dt (None: the eq. 4
    bound; a larger one only with force_dt), as `config` says."""

    def __init__(self, model: ClothModel, collider: Collider | None = None, config: StepConfig = StepConfig(),
                 dt: float | None = None, force_dt: bool = False, gravity: np.ndarray = GRAVITY):
        self.model, self.collider, self.config = model, collider, config
        self.force_dt = force_dt
        self.dt = self._checked_dt(model, model.dt_bound if dt is None else dt)
        self.gravity = np.asarray(gravity, dtype=np.float64)
        faces_by_collider = collider is not None and collider.makes_face_points
        self.buf = StepBuffers.make(model, config, faces_by_collider)
        if faces_by_collider:
            collider.fill_faces(model.n, model.quads, model.tris)
        m = len(self.buf.points)
        self.answers = None if collider is None else CarriedAnswers(collider, config, m, model.params.tolerance)
        self.schedule = CheckSchedule()
        self.self_contact = (SelfContact(model, config.self_thickness, config.self_every)
                             if config.self_collision else None)
        self.timing = {"cloth": 0.0, "collision": 0.0}
        self.iterations = 0
        self.last_hits = 0  # points in contact at the last collision check
        self.guarded = 0  # springs the strain guard shortened in its last pass
        self.guard_pending = False  # (late guard) positions integrated and not yet guarded
        self._n_near = 0  # listed springs near the guard's length (late guard)
        self._slow_held = False  # the held forces hold something (else the next pass evaluates them)
        self._control = Control()

    def _checked_dt(self, model: ClothModel, dt: float) -> float:
        if not (dt > 0 and np.isfinite(dt)):
            raise InputError(f"time step must be positive, got {dt}")
        if dt > model.dt_bound * (1 + 1e-9) and not self.force_dt:
            raise InputError(f"time step {dt * 1e3:.3f} ms exceeds the stability bound of eq. 4 "
                             f"({model.dt_bound * 1e3:.3f} ms for this fabric and mesh); use a smaller one "
                             "or force it (--force-dt)")
        return float(dt)

    @property
    def f(self) -> np.ndarray:
        """(N, 3) the forces of the last step that kept them (StepConfig.keep_forces)."""
        return self.buf.f

    def step(self, state: ClothState, control: Control | None = None) -> None:
        m, cfg, buf, dt = self.model, self.config, self.buf, self.dt
        c = control if control is not None else self._control
        sewing = c.sewing
        recover = max(cfg.recover if sewing is None else NO_RECOVERY, dt)  # (at least a step: no overshoot)
        forcing = Forcing(self.gravity * c.gravity_scale, m.params.damping * c.damping_scale,
                          m.fabric.friction * c.friction_scale)
        t0 = time.perf_counter()
        # forces (eq. 2, gravity, damping, the reaction force eq. 16) and v += dt f / m (eq. 3);
        # the same pass lists the over-elongated springs
        n_over = self._forces(state, forcing, sewing is None)
        if self.guard_pending:  # the late guard of the last step's positions, from that list
            self.guarded = passes.guard_listed(m, state, buf, cfg, n_over, self._n_near)
            self.guard_pending = False
        # velocity modification against super-elasticity (seed 003 §4.3, seed 000 eq. 5/6)
        n_act = passes.modify_velocities(m, state, buf, cfg, forcing.gravity, dt, recover, n_over)
        if sewing is not None:  # (before the collision response: nothing is sewn into the body)
            passes.sew(m, state, buf, sewing, dt)
        if c.attachment is not None:
            passes.attach(state, c.attachment)
        if c.floor is not None:
            passes.floor(state, c.floor, dt, forcing.friction)
        t1 = time.perf_counter()
        # cloth-cloth contact within the cloth, every self_every steps (before the body's
        # response: the body has the last word)
        if self.self_contact is not None:
            self.self_contact.step(state, self.iterations, dt, 1.0 / cfg.push_time, forcing.friction,
                                   None if sewing is None else sewing.pairs)
        # collision detection and response (vertices and face points, eq. 12/15) every
        # collide_every steps, the points predicted that far ahead, alternated with the strain
        # limit; in between, the reaction force and the held contacts keep cloth out of the body
        ahead = self.schedule.now(c.collide_every, self.iterations) if self.collider is not None else 0
        if ahead:
            passes.collision_points(state, buf, dt * ahead, buf.points)
            self.last_hits = passes.respond(m, state, buf, cfg, self.answers.answer(buf.points), forcing, dt,
                                            recover, n_act)
            if sewing is not None and cfg.sew_after_contact:
                # (the response sets a point in contact to its faces' mean: a seam end lying on
                # the body lost its pull to its neighbours'; the pull keeps off the body's normal)
                passes.pull(m, state, buf, sewing)
        t2 = time.perf_counter()
        # positions (eq. 3); then Provot's position modification (the comparison mode), or the
        # strain guard: what the velocity modification could not hold (the body pushing a band out)
        passes.integrate(state, buf, dt, hold_contacts=not ahead and self.collider is not None)
        if cfg.mode == VM_PROVOT:
            passes.provot(m, state, buf, cfg)
        elif cfg.strain_guard is not None and sewing is None:
            if cfg.late_guard:
                self.guard_pending = True  # (at the next step's force pass, or finish_guard)
            else:
                self.guarded = passes.guard(m, state, buf, cfg)
        t3 = time.perf_counter()
        self.timing["cloth"] += (t1 - t0) + (t3 - t2)
        self.iterations += 1
        if ahead and self.collider.prefetches:
            self._prefetch(state, c.collide_every)
        self.timing["collision"] += time.perf_counter() - t3 + (t2 - t1)

    def _forces(self, state: ClothState, forcing: Forcing, guarding: bool) -> int:
        """The force pass; returns the springs it listed as past the strain limit."""
        cfg = self.config
        slow_due = self.iterations % cfg.flexion_every == 0 or not self._slow_held
        near_frac = 1e30  # (no listed spring is near the guard's length unless the late guard wants them)
        if cfg.late_guard and cfg.strain_guard is not None and guarding:
            near_frac = 0.5 * cfg.strain_guard / (1.0 + self.model.fabric.strain_threshold)
        n_over, self._n_near = passes.eval_forces(self.model, state, self.buf, forcing, self.dt, slow_due, near_frac)
        self._slow_held = True
        return n_over

    def _prefetch(self, state: ClothState, every: float) -> None:
        """Right after a check: the collider starts on the next check's points, predicted from
        here, in the background while the steps in between run."""
        nxt = self.schedule.next(every, self.iterations)
        if nxt is None:
            return
        c, ahead = nxt
        passes.collision_points(state, self.buf, self.dt * (c - self.iterations + ahead), self.buf.pre_points)
        self.collider.prefetch(self.buf.pre_points, (c - self.iterations + 1) * self.dt)

    def checks_next(self, control: Control) -> bool:
        """Whether the next step checks collisions (a moving body's collider is put at the step's
        time only for those)."""
        return self.collider is not None and self.schedule.due(control.collide_every, self.iterations)

    def finish_guard(self, state: ClothState) -> None:
        """(late guard) The strain guard of the last step's positions, now (before they are read)."""
        if self.guard_pending:
            t0 = time.perf_counter()
            self.guarded = passes.guard(self.model, state, self.buf, self.config)
            self.timing["cloth"] += time.perf_counter() - t0
        self.guard_pending = False

    def set_collider(self, collider: Collider) -> None:
        """Go on against `collider` (the same body seen whole, after some cloth passed through parts
        of it): the answers carried from the old one are dropped."""
        self.collider = collider
        self.answers = CarriedAnswers(collider, self.config, len(self.buf.points), self.model.params.tolerance)

    def restiffen(self, model: ClothModel, dt: float) -> None:
        """Go on with `model` -- the same cloth with other spring stiffness
        (engine.cloth.model.with_stiffness) -- at step dt, keeping contacts, carried answers and
        counters."""
        old = self.model
        if model.springs.shape != old.springs.shape or not np.array_equal(model.springs, old.springs):
            raise ValueError("restiffen: the model must have the same springs")
        self.dt = self._checked_dt(model, dt)
        self.model = model
        self.buf.restiffen(model)
        if self.self_contact is not None:
            self.self_contact.model = model  # (its masses)

    def kinetic_energy(self, state: ClothState) -> float:
        return float(kinetic_energy(state.v, self.model.mass))

    def max_strain(self, state: ClothState) -> float:
        return float(max_strain(state.x, self.model.springs, self.model.limit_rest, self.model.strain_limited))
