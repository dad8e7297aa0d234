"""The cloth step, read like seed 003's algorithm: forces, integrate, modify velocities, collide.

Example:
    model = build_model(garment.uv, garment.panel, garment.lattice, garment.quads, garment.tris,
                        garment.seams, get_fabric("cotton"), h=0.015)
    state = ClothState(garment.positions.copy(), np.zeros_like(garment.positions))
    solver = ClothSolver(model, collider)          # dt from eq. 4 unless given
    for _ in range(1000):
        solver.step(state)

A collider answers, for M points, (status (M,) int8: 0 clear / 1 in the tolerance band /
2 inside, normal (M, 3), body velocity (M, 3), depth (M,) metres past the band's outer edge).
"""

from __future__ import annotations

import math
import time
from typing import Protocol

import numpy as np

from engine.cloth import kernels as K
from engine.cloth.model import FLEXION, SHEAR, ClothModel, ClothState, spring_runs
from engine.cloth.welds import pull_seams
from engine.errors import InputError

GRAVITY = np.array([0.0, -9.81, 0.0])


class Collider(Protocol):
    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]: ...


class FireRelaxer:
    """FIRE 2.0 (Bitzek, Koskinen, Gähler, Moseler & Gumbsch, "Structural relaxation made simple",
    Phys. Rev. Lett. 97, 170201, 2006; Guénolé et al., "Assessment and optimization of the fast
    inertial relaxation engine (FIRE) for energy minimization in atomistic simulations and its
    implementation in LAMMPS", Comput. Mater. Sci. 175, 109584, 2020) on the cloth's velocities,
    for stages that only want the cloth at rest (the drape): after each solver step, while the
    cloth's power P = f.v is positive its velocity is turned a fraction alpha toward the force
    (alpha decays while P stays positive); as soon as P turns negative -- the cloth starts
    climbing back up, the swing of an oscillation -- the positions go back half that step and
    every velocity is zeroed. Viscous damping instead slows the cloth's slow modes as much as its
    fast ones (measured on the dress: the hem crept down at ~1 cm/s for 2 s of draping). The
    time step stays at the eq. 4 bound (FIRE's growing step is left out); the half step back is
    what keeps that stable: zeroed velocities alone make each restart a gradient step, which at
    the eq. 4 step grows the stiffest modes (tests/test_cloth.py). The power is the whole
    cloth's: zeroing, as well, each vertex whose own f.v is negative (a local swing; QuickMin-like)
    held the cloth back from sliding into place -- measured on the catalogue's five garments in M
    on default:female and default:male, 305k iterations instead of 28.5k, five not settled.
    Nor another alpha (scripts/bench_ab.py --settle 3 --edge-cm 2, mean iterations against these
    defaults, 2026-12-04): alpha kept at least 0.02, 2.03 x; decay 0.9, 1.40 x (one drape did not
    settle). The totals of that comparison spread +-15 % from 1 nm moves of the start alone."""

    def __init__(self, alpha: float = 0.1, decay: float = 0.99, delay: int = 5):
        self.alpha0, self.decay, self.delay = alpha, decay, delay
        self.alpha, self.run, self.restarts = alpha, 0, 0

    def after_step(self, solver: "ClothSolver", state: ClothState) -> None:
        if K.fire_mix(solver.f, state.v, state.x, solver.dt, self.alpha) > 0.0:
            self.run += 1
            if self.run > self.delay:
                self.alpha *= self.decay
        else:
            self.alpha, self.run = self.alpha0, 0
            self.restarts += 1


class ClothSolver:
    """Explicit mass-spring solver with velocity modification and map-based collision."""

    def __init__(self, model: ClothModel, collider: Collider | None = None, dt: float | None = None,
                 force_dt: bool = False, gravity: np.ndarray = GRAVITY):
        if dt is None:
            dt = model.dt_bound
        if not (dt > 0 and np.isfinite(dt)):
            raise InputError(f"time step must be positive, got {dt}")
        if dt > model.dt_bound * (1 + 1e-9) and not force_dt:
            raise InputError(f"time step {dt * 1e3:.3f} ms exceeds the stability bound of eq. 4 "
                             f"({model.dt_bound * 1e3:.3f} ms for this fabric and mesh); use a smaller one "
                             "or force it (--force-dt)")
        self.model, self.collider, self.dt = model, collider, float(dt)
        self.force_dt = force_dt
        self.gravity = np.asarray(gravity, dtype=np.float64)
        p = model.params
        self.mode = K.VM_MODES.get(p.velocity_mode)
        if self.mode is None:
            raise InputError(f"unknown velocity modification '{p.velocity_mode}'; "
                             f"choose one of: {', '.join(K.VM_MODES)}")
        n = model.n
        self.active = model.kind != FLEXION  # flexion springs may shorten/lengthen with folds
        self.f = np.zeros((n, 3))
        self._f_kept = self.f  # where the force pass writes them (drop_forces)
        # the force pass's spring order and buffers (engine.cloth.model.SpringRuns)
        self.runs = model.runs
        self._soa = np.zeros((9, n))  # (also the strain guard's work buffer)
        self._use_precision(np.float64)
        self._listed = np.zeros(-(-len(model.springs) // 8) * 8, dtype=np.uint8)
        self._listed_words = self._listed.view(np.uint64)
        self._geo_s = np.zeros((len(model.springs), 4))
        self.vm_work = np.zeros(len(model.springs), dtype=np.int32)
        self.vm_geo = np.zeros((len(model.springs), 4))  # the listed springs' direction, excess
        self.vm_ends = np.zeros((len(model.springs), 2), dtype=np.int32)  # ... and ends
        self._near = np.zeros(len(model.springs), dtype=np.int32)  # ... those near the guard's length (late_guard)
        self._n_near = 0
        self.contact = np.zeros(n, dtype=np.bool_)
        self.contact_n = np.zeros((n, 3))
        self.body_v = np.zeros((n, 3))
        m = n + len(model.quads) + len(model.tris)
        self.points = np.zeros((m, 3))
        self.pre_points = np.zeros((m, 3))  # the next check's points, predicted (_prefetch)
        self.hit_buf = np.zeros(m, dtype=np.int32)  # work buffers of K.contact_rounds
        self.touched_buf = np.zeros(n, dtype=np.int32)
        self.ask_rows = np.zeros(m, dtype=np.int64)  # points to ask the collider alone (_contacts)
        # the faces whose points this solver writes into points (K.collision_points): none when
        # the collider makes them itself (a collider with fill_faces)
        self._faces = (model.quads, model.tris)
        if collider is not None and hasattr(collider, "fill_faces"):
            collider.fill_faces(n, model.quads, model.tris)
            self._faces = (model.quads[:0], model.tris[:0])
        self._no_rows = np.zeros(0, dtype=np.int64)
        self.timing = {"cloth": 0.0, "collision": 0.0}
        self.iterations = 0
        self.last_hits = 0
        self.strain_guard = p.strain_guard  # the drape turns it off while sewing
        self.guarded = 0  # springs the strain guard shortened in the last step
        self.x_guard = np.zeros((n, 3))  # positions before the guard moved them (K.guard_positions)
        self._saved = np.zeros(n, dtype=np.uint8)  # ... which points those are
        self._saved_list = np.zeros(n, dtype=np.int32)
        self._guard_lim2 = (None, None)  # (threshold, squared lengths the guard looks past, run order)
        self._late = None  # late_guard: (threshold, the squared lengths past which a listed spring is flagged)
        self._guard_work = None  # ... and the springs it projects
        self.guard_pending = False  # late_guard: positions integrated and not yet guarded
        self.recover = p.recover  # ... and the strain recovery (it would fight the seam pull)
        self.collide_every = p.collide_every  # steps between collision checks (the drape sets it per stage)
        self.sewing = None  # (pairs, welded, tau, vmax) while sewing: see engine.cloth.welds
        self._q, self._q_age, self._q_version = None, 0, None  # the last map answer (see _contacts)
        self._schedule = None  # a fractional collide_every's check schedule (_check_now)

    def _use_precision(self, dtype) -> None:
        """The force pass's buffers and spring properties in `dtype` (K.eval_forces_and_integrate)."""
        m, r, n = self.model, self.runs, self.model.n
        self._fdtype = dtype
        self._one, self._tiny = dtype(1.0), dtype(1e-30)
        self._sprops = self._spring_props(m)
        self._fsoa = self._soa if dtype == np.float64 else np.zeros((9, n), dtype)
        self._f_slow = np.zeros((3, n), dtype)  # the flexion springs' forces, as last evaluated (flexion_every)
        self._run_tmp = np.zeros((3, r.longest), dtype)
        self._lengths = np.zeros(len(m.springs), dtype)
        self._slow_held = False  # f_slow holds nothing yet: the next pass evaluates the slow group

    def single_precision_forces(self) -> None:
        """Compute the spring forces in single precision from now on (velocities and positions
        stay double): the force pass's vector loops take twice the springs an instruction
        (measured on the walking dress's runs: 2.8 instead of 4.5 ns a spring). A spring of
        1.6 cm is then measured to ~1e-7 m (1.7 m from the origin), its force to ~1e-5 N -- a
        few thousandths of a vertex's weight. The walk uses it (engine.scene.walk); the drape
        stays double (it turns on the last bits of the forces: engine.cloth's history). Starts
        the slow group's held forces afresh (they are evaluated at the next due step)."""
        self._use_precision(np.float32)

    def hold_shear(self) -> None:
        """Evaluate the shear springs' forces with the slow group from now on (every
        flexion_every steps, held in between), while still listing them for the strain limit
        every step (engine.cloth.model.SpringRuns' held springs). A shear spring is ~200 x
        softer than a stretch spring (engine.cloth.fabrics: cotton 0.38 against 82 N/m at the
        walk's stiffness); the stretch springs set the eq. 4 step. The walk uses it; the drape
        does not (it stays as it was, bit for bit)."""
        m = self.model
        if not (m.kind == SHEAR).any():
            return
        self.runs = spring_runs(m.springs, slow=m.kind == FLEXION, held=m.kind == SHEAR)
        self._use_precision(self._fdtype)
        self._guard_lim2 = (None, None)

    def drop_forces(self) -> None:
        """Stop keeping the force pass's forces in self.f (FIRE and diagnostics read them; the
        walk does not): (N, 3) doubles less written every step. A walking step goes through
        ~1.9 MB on the solver's core, more than its 1 MiB L2, so what it writes comes back from
        the shared L3 -- or, when the host's other work has taken that, from memory (measured
        on a captured walking step of the dress: the force pass 67 us after 8 MB of other data,
        156 us after 64 MB; without f 80 against 84 us after 16 MB, 166 against 171 after 64).
        self.f then keeps the forces of the last step that kept them."""
        self._f_kept = np.zeros((0, 3))

    def late_guard(self) -> None:
        """Run the strain guard at the start of the next step, right after its force pass,
        instead of at the end of this one: the force pass measures every spring on those same
        positions and lists the long ones for the velocity modification, and the guard's long
        springs are among them (K.guard_listed), so the guard's own pass over every spring
        goes (K.guard_positions; measured on eight captured walking steps of the dress, 3,883
        vertices: guard_positions 20-36 us, ~17.5 of them that pass; guard_listed 11-21 us;
        a walking step takes ~300 us). The guard
        gives the same positions it would have given; what differs is that the next step's
        forces are taken before it (a spring past threshold + guard pulls for one step) and
        that the listed springs the guard moved are measured again for the velocity
        modification (one made long by a projection waits a step).
        Positions read between steps are then not guarded yet (guard_pending): finish_guard
        guards them (the walk does at the end of every frame). The walk uses it; the drape
        does not."""
        self._late = (None, None)
        self._guard_work = np.zeros(len(self.model.springs), dtype=np.int32)

    def finish_guard(self, state: ClothState) -> None:
        """With late_guard: the strain guard of the last step's positions, now (K.guard_positions)."""
        if self.guard_pending:
            t0 = time.perf_counter()
            self._guard(state)
            self.timing["cloth"] += time.perf_counter() - t0
        self.guard_pending = False

    def _guard(self, state: ClothState) -> None:
        """The strain guard (K.guard_positions) of state's positions."""
        m, p, r = self.model, self.model.params, self.runs
        thr = m.fabric.strain_threshold + self.strain_guard
        self.guarded = K.guard_positions(state.x, state.v, m.springs, m.rest, self.active, thr, m.inv_mass,
                                         p.vm_passes, self.vm_work, self.contact, self.contact_n, p.guard_step,
                                         r.fast.perm, r.fast.runs, r.fast.springs, r.n_run,
                                         self._guard_limits(thr), self._soa,
                                         self._listed, self._listed_words, m.adj_ptr, m.adj_spring,
                                         self.x_guard, self._saved, self._saved_list)

    def _guard_listed(self, state: ClothState, n_over: int) -> None:
        """late_guard's strain guard of state's positions (K.guard_listed), from the force pass's
        list of its n_over long springs."""
        m, p = self.model, self.model.params
        thr = m.fabric.strain_threshold + self.strain_guard
        self.guarded = K.guard_listed(state.x, state.v, m.springs, m.rest, self.active, thr, m.inv_mass,
                                      p.vm_passes, self._guard_work, self.contact, self.contact_n, p.guard_step,
                                      self._listed, self._listed_words, m.adj_ptr, m.adj_spring,
                                      self.x_guard, self._saved, self._saved_list,
                                      self.vm_work, self.vm_geo, self.vm_ends, n_over, self._near, self._n_near,
                                      self._late_limits(thr), m.fabric.strain_threshold)
        self.guard_pending = False

    def _late_limits(self, threshold: float) -> np.ndarray:
        """late_guard's lim2 (K.guard_listed; by model index): a hair below the squared length
        at which a spring passes the guard's threshold (inf for the springs the strain limit
        leaves alone)."""
        if self._late[0] != threshold:
            m = self.model
            lim = (1.0 + threshold) * m.rest
            self._late = (threshold, np.ascontiguousarray(np.where(self.active, lim * lim * (1.0 - 1e-9), np.inf)))
        return self._late[1]

    def _near_frac(self) -> float:
        """The force pass's near_frac: with late_guard, half the strain guard's excess as a
        fraction of the listing length ((1 + threshold) rest); else none is near (1e30)."""
        if self._late is None or self.strain_guard is None:
            return 1e30
        thr = self.model.fabric.strain_threshold
        return 0.5 * self.strain_guard / (1.0 + thr)

    def _spring_props(self, model: ClothModel) -> np.ndarray:
        """(4, S) rest, stiffness, damping, strain limit (inf: not limited) in the force pass's order."""
        limit = np.where(self.active, (1.0 + model.fabric.strain_threshold) * model.rest, np.inf)
        return np.ascontiguousarray(np.stack([model.rest, model.stiffness, model.spring_c, limit])[:, self.runs.perm],
                                    dtype=self._fdtype)

    def _guard_limits(self, threshold: float) -> np.ndarray:
        """The squared lengths past which K.guard_positions flags a spring (the force pass's
        order, its fast group: flexion springs are never limited): a hair
        below ((1 + threshold) rest)^2 -- a superset of the long ones, whatever the rounding --
        and inf for the springs the strain limit leaves alone."""
        if self._guard_lim2[0] != threshold:
            m = self.model
            lim = (1.0 + threshold) * m.rest
            lim2 = np.where(self.active, lim * lim * (1.0 - 1e-9), np.inf)[self.runs.fast.perm]
            self._guard_lim2 = (threshold, np.ascontiguousarray(lim2))
        return self._guard_lim2[1]

    def restiffen(self, model: ClothModel, dt: float) -> None:
        """Go on with `model` -- the same cloth (springs, masses, rest lengths) with other spring
        stiffness (engine.cloth.model.with_stiffness) -- at step dt, keeping the contacts, the
        carried map answers and the counters."""
        old = self.model
        if model.springs.shape != old.springs.shape or not np.array_equal(model.springs, old.springs):
            raise ValueError("restiffen: the model must have the same springs")
        if dt > model.dt_bound * (1 + 1e-9) and not self.force_dt:
            raise InputError(f"time step {dt * 1e3:.3f} ms exceeds the stability bound of eq. 4 "
                             f"({model.dt_bound * 1e3:.3f} ms)")
        self.model, self.dt = model, float(dt)
        self.collide_every = model.params.collide_every
        self._sprops = self._spring_props(model)
        self._guard_lim2 = (None, None)
        if self._late is not None:
            self._late = (None, None)

    def _forces(self, state: ClothState, g: np.ndarray, damping_scale: float, friction_scale: float) -> int:
        """The force pass (K.eval_forces_and_integrate) on state: v += dt f / m; lists the
        springs past the strain limit (vm_work, vm_geo, vm_ends; with late_guard those near the
        guard's length in _near, _n_near) and returns their count."""
        m, p, dt, r = self.model, self.model.params, self.dt, self.runs
        n_over, self._n_near = K.eval_forces_and_integrate(
            state.x, state.v, m.inv_mass, m.mass, r.springs, r.perm, r.runs, r.n_run, self._sprops, g,
            p.damping * damping_scale, self.contact, self.contact_n, m.fabric.friction * friction_scale, dt,
            self._f_kept, self.vm_work, self.vm_geo, self._fsoa, self._run_tmp, self._lengths, self._listed,
            self._listed_words, self._geo_s, r.r_fast, r.n_fast, r.n_run_slow,
            self.iterations % p.flexion_every == 0 or not self._slow_held, self._f_slow, self._one, self._tiny,
            r.r_held, m.springs, self.vm_ends, self._near, self._near_frac())
        self._slow_held = True
        return n_over

    def step(self, state: ClothState, gravity_scale: float = 1.0, damping_scale: float = 1.0,
             friction_scale: float = 1.0) -> None:
        m, p, dt = self.model, self.model.params, self.dt
        recover = max(self.recover, dt)  # work an excess off over at least one step (no overshoot)
        g = self.gravity * gravity_scale
        t0 = time.perf_counter()
        # forces (eq. 2, gravity, damping, reaction eq. 16) and v += dt a (eq. 3); the same pass
        # lists the over-elongated springs for the velocity modification
        n_over = self._forces(state, g, damping_scale, friction_scale)
        if self.guard_pending:  # late_guard: the last step's positions, guarded from the force pass's list
            self._guard_listed(state, n_over)
        # velocity modification against super-elasticity (seed 003 §4.3, seed 000 §3)
        n_act = K.modify_velocities(state.x, state.v, m.springs, m.rest, self.active, m.fabric.strain_threshold,
                                    self.mode, g, dt, self.body_v, p.vm_passes,
                                    self.vm_work, self.vm_geo, self.vm_ends, recover, n_over)
        if self.sewing is not None:
            # sewing has priority over the strain limit (it stretches cloth near a seam by
            # design; the drape's strain recovery relaxes that), but not over the collision below
            pairs, welded, tau, vmax = self.sewing
            pull_seams(state.x, state.v, m.mass, pairs, welded, tau, vmax, self.contact, self.contact_n)
        t1 = time.perf_counter()
        # collision detection and response (vertices and face midpoints, eq. 12/15) every
        # `collide_every` steps, the points predicted that many steps ahead; in between the
        # reaction force (eq. 16, in the force pass) keeps contacts from pressing in, and
        # hold_contacts keeps the strain limit and the seams from moving them in
        ahead = self._check_now(self.collide_every) if self.collider is not None else 0
        if ahead:
            K.collision_points(state.x, state.v, dt * ahead, *self._faces, self.points)
            status, normal, bvel, depth = self._contacts()
            # The body's push and the strain limit can disagree (a waistband sliding down the hips
            # is pushed outward while it may not stretch): alternate the two velocity changes a
            # few rounds on the same contacts -- this converges to "stop sliding" -- and end on the
            # collision response so nothing moves into the body.
            self.last_hits = K.contact_rounds(state.v, self.vm_ends, self.mode, g, dt,
                                              p.vm_passes, self.vm_work, self.vm_geo, recover, n_act,
                                              p.contact_rounds, status, normal, bvel, depth, m.n, m.quads, m.tris,
                                              p.tolerance, p.reflection, m.fabric.friction * friction_scale,
                                              self.contact, self.contact_n, self.body_v, self.hit_buf,
                                              self.touched_buf, 1.0 / p.push_time)
        t2 = time.perf_counter()
        # positions (eq. 3); Provot's position modification when chosen as the comparison
        if not ahead and self.collider is not None:  # (hold_contacts in the same pass: counted as the cloth's)
            K.hold_and_integrate(state.x, state.v, dt, self.contact, self.contact_n, self.body_v)
        else:
            K.integrate_positions(state.x, state.v, dt)
        if self.mode == K.VM_PROVOT:
            K.provot_positions(state.x, m.springs, m.rest, self.active, m.fabric.strain_threshold,
                               m.inv_mass, p.vm_passes, self.vm_work, False, self.contact, self.contact_n, np.inf)
        elif self.strain_guard is not None:
            # what the velocity modification could not hold (the body pushing a band outward);
            # the velocity that would stretch the guarded springs again goes (K.guard_positions)
            if self._late is not None:
                self.guard_pending = True  # (at the next step's force pass, or finish_guard)
            else:
                self._guard(state)
        t3 = time.perf_counter()
        self.timing["cloth"] += (t1 - t0) + (t3 - t2)
        self.iterations += 1
        if ahead and hasattr(self.collider, "prefetch"):
            self._prefetch(state)
        self.timing["collision"] += time.perf_counter() - t3 + (t2 - t1)

    def _prefetch(self, state: ClothState) -> None:
        """Right after a check: let the collider start on the next check's points, predicted
        from here (x + v dt over the steps until then and the steps that check looks ahead), at
        the body's time of that check -- in the background, while the steps in between run
        (engine.collide.moving.TrackCollider.prefetch)."""
        nxt = self._next_check(self.collide_every)
        if nxt is None:
            return
        c, ahead = nxt
        K.collision_points(state.x, state.v, self.dt * (c - self.iterations + ahead), *self._faces, self.pre_points)
        self.collider.prefetch(self.pre_points, (c - self.iterations + 1) * self.dt)

    def _next_check(self, every: float) -> tuple[int, int] | None:
        """(iteration of the next check, how many steps ahead it will look), as _check_now will
        have them; None if not known yet."""
        e = float(every)
        if e.is_integer():
            e = int(e)
            return -(-self.iterations // e) * e, e
        sched = self._schedule
        if sched is None or sched[0] != e:
            return None
        return sched[3], sched[1] + math.ceil((sched[2] + 1) * e - 1e-9) - sched[3]

    def checks_next(self) -> bool:
        """Whether the next step() checks collisions (and so asks the collider): a moving
        body's collider is put at the step's time only for those (engine.scene.walk)."""
        if self.collider is None:
            return False
        e = float(self.collide_every)
        if e.is_integer():
            return self.iterations % int(e) == 0
        sched = self._schedule
        return sched is None or sched[0] != e or self.iterations >= sched[3]

    def _check_now(self, every: float) -> int:
        """Whether this step checks collisions: 0 if not, else the steps until the next check
        (how far ahead the points are predicted). A whole `every` checks at the iterations it
        divides; a fractional one (the walk's: as often as the body's travel asks, not rounded
        down to whole steps) at start + ceil(k * every), k = 0, 1, ..., start being the iteration
        it was first used at -- checks `every` steps apart on average, floor or ceil of it each."""
        e = float(every)
        if e.is_integer():
            return int(e) if self.iterations % int(e) == 0 else 0
        sched = self._schedule
        if sched is None or sched[0] != e:
            sched = self._schedule = [e, self.iterations, 0, self.iterations]  # every, start, k, next
        if self.iterations < sched[3]:
            return 0
        sched[2] += 1
        sched[3] = sched[1] + math.ceil(sched[2] * e - 1e-9)
        return sched[3] - self.iterations

    def _contacts(self):
        """The collider's answer for self.points. Asking the maps is the costliest part of a step,
        and at the eq. 4 time step a point moves a fraction of a millimetre per step, so the last
        answer is carried forward (depth corrected for the move along the normal,
        K.stale_contacts) until a point moved `requery_move` since the last query, a clear point
        moved as far as it was from the band, `requery_every` steps passed, or the body moved
        (the collider's version changed).
        A collider with `query_rows` is then asked only for the points whose answer may have
        changed (K.rows_to_ask: those in contact, and clear points that moved as far as their
        distance from the band); the others stay clear. Between two such queries a clear point
        that may have reached the band is asked alone. (Measured: asking the contacts only every
        `requery_every` steps instead left kinks at the male trousers' knees; they are asked
        as often as before.)
        A collider with `solver_carries` False (a body that moves every step) is asked every
        time and nothing is kept."""
        p = self.model.params
        c = self.collider
        ver = getattr(c, "version", None)
        q = self._q
        by_rows = hasattr(c, "query_rows")
        if q is not None and ver == self._q_version:
            q_pts, g_pts, q_st, q_n, q_bv, q_d, st, d = q
            # a point asked alone is asked as soon as it may touch the band (so contacts are
            # never missed: measured, with the 0.5 mm slack 90 points a step on the trousers were
            # in the band but taken as clear, and the drapes did not settle)
            reach, slack = p.requery_move, (0.0 if by_rows else 0.1 * p.tolerance)
            if self._q_age < p.requery_every:
                k = K.stale_contacts(self.points, q_pts, g_pts, q_st, q_n, q_d, st, d, reach, slack,
                                     self.ask_rows if by_rows else self._no_rows,
                                     getattr(c, "depth_along_z", False))
                if k >= 0:  # the contacts' answers carry; clear points that may not be clear ask alone
                    self._q_age += 1
                    if k > 0:
                        self._ask_rows(k, q)
                    return st, q_n, q_bv, d
            if by_rows:
                self._ask_rows(K.rows_to_ask(self.points, q_pts, q_st, q_d, reach, slack, self.ask_rows), q)
                g_pts[:] = self.points
                self._q_age = 1
                return st, q_n, q_bv, d
        status, normal, bvel, depth = c.query(self.points)
        if p.requery_every > 1 and getattr(c, "solver_carries", True):
            self._q = (self.points.copy(), self.points.copy(), status.copy(), normal.copy(), bvel.copy(),
                       depth.copy(), status.copy(), depth.copy())
        self._q_age, self._q_version = 1, ver
        return status, normal, bvel, depth

    def _ask_rows(self, k: int, q: tuple) -> None:
        """Ask the collider for the points in self.ask_rows[:k] alone; keep their answers in q."""
        q_pts, _, q_st, q_n, q_bv, q_d, st, d = q
        status, normal, bvel, depth = self.collider.query_rows(self.points, self.ask_rows, k)
        K.keep_rows(self.ask_rows, k, self.points, status, normal, bvel, depth, q_pts, q_st, q_n, q_bv, q_d, st, d)

    def kinetic_energy(self, state: ClothState) -> float:
        return float(K.kinetic_energy(state.v, self.model.mass))

    def max_strain(self, state: ClothState) -> float:
        return float(K.max_strain(state.x, self.model.springs, self.model.rest, self.active))
