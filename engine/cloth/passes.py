"""The passes of one cloth step, each a small wrapper over its numba kernel (engine.cloth.kernels_*):
(model, state, buffers, ...) in, the state changed in place. engine.cloth.solver calls them in the
order of seed 003's algorithm."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from engine.cloth import kernels_contact as KC
from engine.cloth import kernels_forces as KF
from engine.cloth import kernels_integrate as KI
from engine.cloth import kernels_strain as KS
from engine.cloth.buffers import StepBuffers
from engine.cloth.config import Attachment, Sewing, StepConfig
from engine.cloth.model import ClothModel, ClothState
from engine.cloth.welds import damp_about_panels, hold_on_planes, pull_seams, rest_on_floor
from engine.collide.base import Answer


class Forcing(NamedTuple):
    """The external terms of a step: gravity (3,) m/s^2, viscous damping per unit mass (1/s),
    cloth-body friction coefficient."""

    gravity: np.ndarray
    damping: float
    friction: float


def eval_forces(model: ClothModel, state: ClothState, buf: StepBuffers, forcing: Forcing, dt: float,
                slow_due: bool, near_frac: float) -> tuple[int, int]:
    """Springs (eq. 2), gravity, damping, the reaction force (seed 000 eq. 16) and v += dt f / m
    (the velocity half of eq. 3). Lists the springs past the strain limit (buf.work, geo, ends)
    and those near the guard's length (buf.near: past the listing length by near_frac of it);
    returns (listed, near). slow_due: evaluate the held (flexion) springs' forces this step."""
    r = buf.runs
    return KF.eval_forces_and_integrate(
        state.x, state.v, model.inv_mass, model.mass, r.springs, r.perm, r.runs, r.n_run, buf.sprops,
        forcing.gravity, forcing.damping, buf.contact, buf.contact_n, forcing.friction, dt, buf.f_out, buf.work,
        buf.geo, buf.fsoa, buf.run_tmp, buf.lengths, buf.listed, buf.listed_words, buf.geo_s, r.r_fast, r.n_fast,
        r.n_run_slow, slow_due, buf.f_slow, buf.one, buf.tiny, r.r_held, model.springs, buf.ends, buf.near,
        near_frac)


def modify_velocities(model: ClothModel, state: ClothState, buf: StepBuffers, config: StepConfig,
                      gravity: np.ndarray, dt: float, recover: float, n_listed: int) -> int:
    """The velocity modification against super-elasticity (seed 003 §4.3, seed 000 eq. 5/6) over
    the n_listed springs the force pass listed; returns their count."""
    return KS.modify_velocities(state.x, state.v, model.springs, model.limit_rest, model.strain_limited,
                                model.fabric.strain_threshold, config.mode, gravity, dt, buf.body_v,
                                config.vm_passes, buf.work, buf.geo, buf.ends, recover, n_listed)


def sew(model: ClothModel, state: ClothState, buf: StepBuffers, sewing: Sewing, dt: float) -> None:
    """The open seam pairs pulled shut (never into the body); a flat layout's panels then damped
    toward their own mean motion (Sewing.panel_damping)."""
    pull(model, state, buf, sewing)
    if sewing.panel is not None and sewing.panel_damping > 0.0:
        damp_about_panels(state.v, model.mass, sewing.panel, int(sewing.panel.max()) + 1,
                          float(np.exp(-sewing.panel_damping * dt)))


def pull(model: ClothModel, state: ClothState, buf: StepBuffers, sewing: Sewing) -> None:
    """The open seam pairs pulled shut (never into the body): sew's first part, and alone again
    after the collision response (StepConfig.sew_after_contact)."""
    meet, meet_on = sewing.meeting()
    pull_seams(state.x, state.v, model.mass, sewing.pairs, sewing.welded, sewing.tau, sewing.vmax, buf.contact,
               buf.contact_n, meet, meet_on)


def attach(state: ClothState, attachment: Attachment) -> None:
    """The attached vertices brought to their planes (the velocity along each plane kept)."""
    a = attachment
    hold_on_planes(state.x, state.v, a.vertices, a.points, a.normals, a.tau, a.vmax)


FLOOR_VMAX = 1.0  # m/s: cloth placed under the ground comes up at most this fast (a jolt otherwise)


def floor(state: ClothState, y0: float, dt: float, mu: float) -> None:
    """The cloth kept above the ground at y0 (Control.floor), with friction mu along it."""
    rest_on_floor(state.x, state.v, y0, dt, mu, FLOOR_VMAX)


def collision_points(state: ClothState, buf: StepBuffers, ahead: float, out: np.ndarray) -> None:
    """The checked points `ahead` seconds on (x + ahead v; faces' points from them) into out."""
    KC.collision_points(state.x, state.v, ahead, *buf.faces, out)


def respond(model: ClothModel, state: ClothState, buf: StepBuffers, config: StepConfig, answer: Answer,
            forcing: Forcing, dt: float, recover: float, n_listed: int) -> int:
    """The collision response (seed 003 eq. 12, seed 000 eq. 15) of the points in contact,
    alternated config.contact_rounds times with the strain limit on the listed springs; marks the
    contacts for the reaction force. Returns the points in contact."""
    status, normal, body_v, depth = answer
    p = model.params
    return KC.contact_rounds(state.v, buf.ends, config.mode, forcing.gravity, dt, config.vm_passes, buf.work,
                             buf.geo, recover, n_listed, config.contact_rounds, status, normal, body_v, depth,
                             model.n, model.quads, model.tris, p.tolerance, p.reflection, forcing.friction,
                             buf.contact, buf.contact_n, buf.body_v, buf.hit_buf, buf.touched_buf,
                             1.0 / config.push_time)


def integrate(state: ClothState, buf: StepBuffers, dt: float, hold_contacts: bool) -> None:
    """The position half of eq. 3, x += dt v; with hold_contacts (a step between collision
    checks) a vertex in contact at the last check first loses its velocity into the body."""
    if hold_contacts:
        KI.hold_and_integrate(state.x, state.v, dt, buf.contact, buf.contact_n, buf.body_v)
    else:
        KI.integrate_positions(state.x, state.v, dt)


def provot(model: ClothModel, state: ClothState, buf: StepBuffers, config: StepConfig) -> int:
    """Provot's position modification (the comparison mode): springs past the strain limit
    shortened back to it; returns how many were."""
    return KS.provot_positions(state.x, model.springs, model.limit_rest, model.strain_limited,
                               model.fabric.strain_threshold, model.inv_mass, config.vm_passes, buf.work, False,
                               buf.contact, buf.contact_n, np.inf)


def guard(model: ClothModel, state: ClothState, buf: StepBuffers, config: StepConfig) -> int:
    """The strain guard: springs past the fabric's threshold + config.strain_guard shortened back
    (never into the body), the moved points' velocity back against the move taken away; returns
    the springs it shortened."""
    r = buf.runs.fast
    return KS.guard_positions(state.x, state.v, model.springs, model.limit_rest, model.strain_limited,
                              _guard_threshold(model, config), model.inv_mass, config.vm_passes, buf.work,
                              buf.contact, buf.contact_n, config.guard_step, r.perm, r.runs, r.springs, r.n_run,
                              buf.guard_lim2, buf.soa, buf.listed, buf.listed_words, model.adj_ptr, model.adj_spring,
                              buf.x_guard, buf.saved, buf.saved_list)


def guard_listed(model: ClothModel, state: ClothState, buf: StepBuffers, config: StepConfig, n_listed: int,
                 n_near: int) -> int:
    """The strain guard of `guard`, the same positions bit for bit, found from the force pass's
    list (the late guard: run right after the next step's force pass); the listed springs it
    moved are measured again for the velocity modification."""
    return KS.guard_listed(state.x, state.v, model.springs, model.limit_rest, model.strain_limited,
                           _guard_threshold(model, config), model.inv_mass, config.vm_passes, buf.guard_work,
                           buf.contact, buf.contact_n, config.guard_step, buf.listed, buf.listed_words,
                           model.adj_ptr, model.adj_spring, buf.x_guard, buf.saved, buf.saved_list, buf.work,
                           buf.geo, buf.ends, n_listed, buf.near, n_near, buf.late_lim2,
                           model.fabric.strain_threshold)


def _guard_threshold(model: ClothModel, config: StepConfig) -> float:
    return model.fabric.strain_threshold + config.strain_guard
