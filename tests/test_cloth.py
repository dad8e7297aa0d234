"""The cloth model (springs, masses, eq. 4 time step), the solver's refusals and free fall, the
velocity modification kernel, seam welding helpers and fabrics."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from engine.cloth import kernels_carry as KR
from engine.cloth import kernels_contact as KC
from engine.cloth import kernels_integrate as KI
from engine.cloth import kernels_strain as KS
from engine.cloth import passes
from engine.cloth.buffers import limits2
from engine.cloth.config import Control, StepConfig
from engine.cloth.fabrics import FABRICS, get_fabric
from engine.cloth.model import (FLEXION, MASS_FLOOR, MASS_SCALE_PERCENTILE, SHEAR, STRUCTURAL, ClothParams, ClothState,
                                build_model, lumped_mass, spring_stiffness, weld_model, with_stiffness)
from engine.cloth.schedule import CheckSchedule
from engine.cloth.solver import GRAVITY, ClothSolver, FireRelaxer
from engine.cloth.welds import merge_map, pull_seams
from engine.collide.base import Collider
from engine.errors import InputError
from engine.garment.garment import build_garment
from engine.pattern.spec import PatternSpec
from engine.scene.tuning import Tuning

H = 0.02
SIDE = 0.20  # m


def square_spec(side_cm: float = 20.0) -> PatternSpec:
    s = side_cm
    return PatternSpec.model_validate({"pattern": {"panels": {"square": {
        "vertices": [[0, 0], [s, 0], [s, s], [0, s]],
        "edges": [{"endpoints": [i, (i + 1) % 4]} for i in range(4)],
        "translation": [0, 100, 0]}}, "stitches": []}})


@pytest.fixture(scope="module", autouse=True)
def one_numba_thread():
    """These meshes are tiny: with the machine's cores busy, parallel kernels spend 100x longer
    waiting for their threads than computing (measured 7.9 s vs 0.013 s for 500 steps)."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


@pytest.fixture(scope="module")
def garment():
    return build_garment(square_spec(), h=H)


def _model(garment, fabric="cotton", params=None):
    g = garment
    return build_model(g.uv, g.panel, g.lattice, g.quads, g.tris, g.seams, get_fabric(fabric), H, params)


@pytest.fixture(scope="module")
def model(garment):
    return _model(garment)


# --- model -------------------------------------------------------------------------------------------

def test_spring_kinds_and_rest_lengths(model, garment):
    for kind in (STRUCTURAL, SHEAR, FLEXION):
        assert (model.kind == kind).sum() > 0
    assert np.all(model.rest > 0)
    # rest lengths are the flat (uv) distances
    a, b = model.springs[:, 0], model.springs[:, 1]
    np.testing.assert_allclose(model.rest, np.linalg.norm(garment.uv[a] - garment.uv[b], axis=1))
    # no spring twice, none from a vertex to itself, indices in range
    key = np.sort(model.springs, axis=1)
    assert len(np.unique(key, axis=0)) == len(key)
    assert np.all(a != b) and model.springs.min() >= 0 and model.springs.max() < model.n
    # grid springs have the lengths of the grid: h (structural), h sqrt 2 (shear), 2h (flexion on grid)
    shear = model.kind == SHEAR
    np.testing.assert_allclose(model.rest[shear], H * np.sqrt(2), rtol=1e-9)
    assert np.any(np.isclose(model.rest[model.kind == FLEXION], 2 * H))
    # every mesh edge is a structural spring
    q = garment.quads
    edges = np.concatenate([q[:, [0, 1]], q[:, [1, 2]], q[:, [2, 3]], q[:, [3, 0]],
                            garment.tris[:, [0, 1]], garment.tris[:, [1, 2]], garment.tris[:, [2, 0]]])
    structural = {tuple(p) for p in np.sort(model.springs[model.kind == STRUCTURAL], axis=1).tolist()}
    assert {tuple(p) for p in np.sort(edges, axis=1).tolist()} == structural


def test_stiffness_from_fabric(model):
    fab, p = get_fabric("cotton"), ClothParams()
    np.testing.assert_allclose(model.stiffness[model.kind == STRUCTURAL], fab.stretch * p.stiffness_scale)
    np.testing.assert_allclose(model.stiffness[model.kind == SHEAR], fab.shear * p.stiffness_scale)
    np.testing.assert_allclose(model.stiffness[model.kind == FLEXION], fab.bending / H**2)


@pytest.mark.parametrize("fabric", sorted(FABRICS))
def test_mass_is_density_times_area(garment, fabric):
    m = _model(garment, fabric)
    fab = get_fabric(fabric)
    exact = fab.density * SIDE * SIDE
    g = garment
    lumped = lumped_mass(g.uv, g.quads, g.tris, fab.density)
    assert lumped.sum() == pytest.approx(exact, rel=1e-9)  # faces share their mass exactly
    # the floor lifts the outline's sliver vertices: a little extra mass (2.0 % on this small
    # square at h = 2 cm, where the four corners carry 1/6 of a median vertex each)
    floored = np.maximum(lumped, MASS_FLOOR * np.median(lumped))
    # ... and mass scaling lifts the points whose m / K is below the 5th percentile up to it
    k_at = np.bincount(m.springs[:, 0], m.stiffness, m.n) + np.bincount(m.springs[:, 1], m.stiffness, m.n)
    target = np.percentile(floored / k_at, MASS_SCALE_PERCENTILE)
    np.testing.assert_allclose(m.mass, np.maximum(floored, target * k_at))
    lifted = m.mass > floored * (1 + 1e-12)
    assert lifted.sum() <= 0.05 * m.n + 1  # (none on this regular square: its lightest m / K are tied)
    assert np.isclose((m.mass / k_at).min(), target)
    assert exact <= m.mass.sum() <= exact * 1.03
    np.testing.assert_allclose(m.inv_mass * m.mass, 1.0)


@pytest.mark.parametrize("fabric", sorted(FABRICS))
def test_dt_bound_is_eq4(garment, fabric):
    m = _model(garment, fabric)
    k_at = np.zeros(m.n)
    for (a, b), k in zip(m.springs, m.stiffness):
        k_at[a] += k
        k_at[b] += k
    expect = 0.4 * np.pi * np.sqrt(np.min(m.mass / k_at))
    assert m.dt_bound > 0
    assert m.dt_bound == pytest.approx(expect, rel=1e-12)


def test_softer_springs_allow_a_larger_step(garment):
    stiff = _model(garment)
    soft = _model(garment, params=replace(ClothParams(), stiffness_scale=ClothParams().stiffness_scale / 4))
    assert soft.dt_bound > stiff.dt_bound


def test_with_stiffness_scales_stretch_and_shear_only(model):
    soft = with_stiffness(model, 0.25)
    bend = model.kind == FLEXION
    np.testing.assert_array_equal(soft.stiffness[bend], model.stiffness[bend])
    np.testing.assert_allclose(soft.stiffness[~bend], 0.25 * model.stiffness[~bend], rtol=1e-15)
    assert np.array_equal(soft.springs, model.springs) and np.array_equal(soft.rest, model.rest)
    np.testing.assert_allclose(soft.mass, model.mass, rtol=1e-12)  # the same cloth
    assert soft.params.stiffness_scale == pytest.approx(0.25 * model.params.stiffness_scale)
    # eq. 4: the stretch springs set the bound, so a quarter of the stiffness doubles the step
    assert soft.dt_bound == pytest.approx(2.0 * model.dt_bound, rel=1e-3)
    assert with_stiffness(model, 1.0) is model
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(InputError, match="stiffness factor"):
            with_stiffness(model, bad)


def test_with_stiffness_can_lift_the_damping_cap(model):
    """The walk's damping cap (with_stiffness' damping_cap): each spring's damping is what the
    params ask (a fraction of critical) or the cap x m / (dt degree), whichever is less -- so a
    cap twice as high doubles the capped springs' damping and leaves the others; the springs,
    masses and the eq. 4 step stay. At the drape's own cap nothing changes."""
    from engine.cloth.model import DAMPING_CAP

    soft = with_stiffness(model, 0.25)
    more = with_stiffness(model, 0.25, damping_cap=2 * DAMPING_CAP)
    assert np.array_equal(more.stiffness, soft.stiffness) and np.array_equal(more.mass, soft.mass)
    assert more.dt_bound == soft.dt_bound
    a, b = model.springs[:, 0], model.springs[:, 1]
    asked = model.params.spring_damping * 2.0 * np.sqrt(soft.stiffness * np.minimum(soft.mass[a], soft.mass[b]))
    capped = soft.spring_c < asked * (1 - 1e-12)
    assert capped.mean() > 0.3  # the stretch springs at a quarter of their stiffness
    np.testing.assert_allclose(more.spring_c, np.minimum(asked, 2 * soft.spring_c), rtol=1e-12)
    assert np.all(more.spring_c <= asked * (1 + 1e-12))
    np.testing.assert_array_equal(more.spring_c[~capped], soft.spring_c[~capped])
    same = with_stiffness(model, 1.0, damping_cap=DAMPING_CAP)
    assert same is not model and np.array_equal(same.spring_c, model.spring_c)
    for bad in (0.0, 1.5):
        with pytest.raises(InputError, match="damping cap"):
            with_stiffness(model, 0.25, damping_cap=bad)


def test_restiffen_goes_on_as_a_solver_made_for_the_new_model(model, garment):
    """Changing the springs mid-run (the walk's stiffening) continues exactly as a fresh solver
    on the new model would from the same state; a model with other springs, or a step above
    the new model's bound, is refused."""
    x0 = garment.positions.copy()
    x0[:, 1] += 0.01 * np.sin(7.0 * x0[:, 0])  # not flat: the springs work
    soft = with_stiffness(model, 0.25)
    a = ClothState(x0.copy(), np.zeros_like(x0))
    sa = ClothSolver(soft, dt=soft.dt_bound)
    for _ in range(20):
        sa.step(a)
    b = a.copy()
    sa.restiffen(model, model.dt_bound)
    sb = ClothSolver(model, dt=model.dt_bound)
    for _ in range(30):
        sa.step(a)
        sb.step(b)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.v, b.v)
    with pytest.raises(InputError, match="stability bound"):
        sa.restiffen(model, 1.5 * model.dt_bound)
    other = build_model(*[getattr(build_garment(square_spec(16.0), h=H), k)
                          for k in ("uv", "panel", "lattice", "quads", "tris", "seams")], get_fabric("cotton"), H)
    with pytest.raises(ValueError, match="same springs"):
        sa.restiffen(other, other.dt_bound)


def test_model_refuses_bad_stiffness_scale(garment):
    with pytest.raises(InputError, match="stiffness scale"):
        _model(garment, params=replace(ClothParams(), stiffness_scale=0.0))


# --- solver ------------------------------------------------------------------------------------------

def test_solver_refuses_dt_above_the_bound(model):
    with pytest.raises(InputError, match="stability bound"):
        ClothSolver(model, dt=2 * model.dt_bound)
    assert ClothSolver(model, dt=2 * model.dt_bound, force_dt=True).dt == pytest.approx(2 * model.dt_bound)
    assert ClothSolver(model).dt == model.dt_bound  # default: the bound itself
    assert ClothSolver(model, dt=0.5 * model.dt_bound).dt == pytest.approx(0.5 * model.dt_bound)
    for bad in (0.0, -1e-4, float("nan")):
        with pytest.raises(InputError, match="positive"):
            ClothSolver(model, dt=bad, force_dt=True)


def test_solver_refuses_unknown_velocity_mode():
    with pytest.raises(InputError) as ei:
        StepConfig(velocity_mode="sideways")
    assert "sideways" in str(ei.value) and "average" in str(ei.value) and "zero" in str(ei.value)


@pytest.mark.parametrize("field, bad", [("vm_passes", 0), ("contact_rounds", 1.5), ("flexion_every", 17),
                                        ("strain_guard", -0.1), ("push_time", 0.0), ("precision", "half")])
def test_step_config_refuses_absurd_values(field, bad):
    with pytest.raises(InputError, match=field):
        StepConfig(**{field: bad})


@pytest.mark.parametrize("mode", ["average", "zero"])
def test_free_fall(garment, mode):
    m = _model(garment)
    solver = ClothSolver(m, collider=None, config=StepConfig(velocity_mode=mode))
    state = ClothState(garment.positions.copy(), np.zeros_like(garment.positions))
    com0 = (m.mass[:, None] * state.x).sum(0) / m.mass.sum()
    steps = int(round(0.1 / solver.dt))
    for _ in range(steps):
        solver.step(state)
    t = steps * solver.dt
    assert np.all(np.isfinite(state.x)) and np.all(np.isfinite(state.v))
    com = (m.mass[:, None] * state.x).sum(0) / m.mass.sum()
    drop = com0[1] - com[1]
    assert drop == pytest.approx(0.5 * 9.81 * t * t, rel=0.05)
    assert abs(com[0] - com0[0]) < 1e-6 and abs(com[2] - com0[2]) < 1e-6
    # falling as one piece: no stretch
    assert solver.max_strain(state) < 1e-6
    vy = (m.mass * state.v[:, 1]).sum() / m.mass.sum()
    assert vy == pytest.approx(-9.81 * t, rel=0.05)
    assert solver.iterations == steps


def _vibration_energy(garment, spring_damping, steps=400):
    """A flat square given a high-frequency velocity pattern in its plane (neighbours moving
    against each other: the springs' own vibration), no gravity, no viscous damping: kinetic
    energy left after `steps` steps at the eq. 4 bound, as a fraction of the start."""
    m = _model(garment, params=replace(ClothParams(), spring_damping=spring_damping, damping=0.0))
    solver = ClothSolver(m, collider=None, gravity=np.zeros(3))
    rng = np.random.default_rng(3)
    v0 = rng.normal(0.0, 0.05, (m.n, 3))
    normal = np.linalg.svd(garment.positions - garment.positions.mean(0))[2][2]
    v0 -= np.outer(v0 @ normal, normal)
    state = ClothState(garment.positions.copy(), v0 - (m.mass[:, None] * v0).sum(0) / m.mass.sum())
    e0 = solver.kinetic_energy(state)
    for _ in range(steps):
        solver.step(state)
    assert np.all(np.isfinite(state.v))
    return solver.kinetic_energy(state) / e0, m


def test_spring_damping_stills_vibration(garment):
    """Explicit Euler has no damping of its own: without spring damping a vibration keeps most
    of its energy; with the default it dies out (measured on a draped skirt: a median 0.11 m/s
    of vibration after 4 s without it, 0.02 m/s with it)."""
    undamped, _ = _vibration_energy(garment, 0.0)
    damped, m = _vibration_energy(garment, ClothParams().spring_damping)
    assert undamped > 0.3
    assert damped < 0.1 * undamped
    # the damping stays within its stability cap at the step
    assert np.all(m.spring_c > 0) and np.all(np.isfinite(m.spring_c))


def test_spring_damping_leaves_rigid_motion_alone(garment):
    """A cloth moving as one piece has no relative velocity along its springs: no damping."""
    m = _model(garment, params=replace(ClothParams(), damping=0.0))
    solver = ClothSolver(m, collider=None, gravity=np.zeros(3))
    state = ClothState(garment.positions.copy(), np.tile([0.3, -0.2, 0.1], (m.n, 1)))
    for _ in range(100):
        solver.step(state)
    np.testing.assert_allclose(state.v, np.tile([0.3, -0.2, 0.1], (m.n, 1)), atol=1e-9)


def _stretched_sheet_energy(garment, fire: bool, steps=300):
    """A flat square stretched 3 % in its plane and let go, no gravity, no viscous damping (the
    springs' own at its default): its elastic + kinetic energy after `steps` steps at the eq. 4
    bound, as a fraction of the start, and the FIRE relaxer (None when not used)."""
    m = _model(garment, params=replace(ClothParams(), damping=0.0))
    solver = ClothSolver(m, collider=None, gravity=np.zeros(3))
    c = garment.positions.mean(0)
    state = ClothState(c + 1.03 * (garment.positions - c), np.zeros((m.n, 3)))

    def energy():
        s = m.springs
        stretch = np.linalg.norm(state.x[s[:, 1]] - state.x[s[:, 0]], axis=1) - m.rest
        return 0.5 * np.sum(m.stiffness * stretch ** 2) + solver.kinetic_energy(state)

    e0 = energy()
    relax = FireRelaxer() if fire else None
    for _ in range(steps):
        solver.step(state)
        if relax is not None:
            relax.after_step(solver, state)
    assert np.all(np.isfinite(state.x))
    return energy() / e0, relax


@pytest.mark.parametrize("steps", [100, 1000])
def test_fire_brings_a_released_sheet_to_rest_and_keeps_it_there(steps):
    """FIRE (engine.cloth.solver.FireRelaxer), the drape's way to rest: a stretched sheet let go
    swings on, its spring damping slowly taking the energy out; with FIRE the energy is gone
    within 100 steps, and stays gone. (Zeroing the velocities alone, without FIRE 2.0's half step
    back, pumped energy into the stiffest modes once the sheet was at rest -- the zeroed steps
    are gradient steps, unstable at the eq. 4 step: measured 8 x the start after 1000 steps.)"""
    g = build_garment(square_spec(), h=H)
    free, _ = _stretched_sheet_energy(g, fire=False, steps=steps)
    relaxed, relax = _stretched_sheet_energy(g, fire=True, steps=steps)
    assert relaxed < 0.01 * free
    assert relaxed < 1e-3


def test_fire_mix_turns_velocity_toward_the_force_or_stops():
    """One FIRE velocity step: with positive power (f.v > 0) v becomes (1 - a) v + a |v| f / |f|
    (all vertices as one vector) and the positions stay; with negative power the positions go
    back half the step just taken and every velocity is zeroed."""
    f = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    v = np.array([[0.5, 0.5, 0.0], [0.0, 0.0, 1.0]])
    x = np.array([[0.0, 1.0, 0.0], [0.5, 1.0, 0.2]])
    want = 0.9 * v + 0.1 * np.linalg.norm(v) * f / np.linalg.norm(f)
    x1 = x.copy()
    p = KI.fire_mix(f, v, x1, 0.01, 0.1, np.zeros(len(v), dtype=np.bool_))
    assert p == pytest.approx(0.5)
    np.testing.assert_allclose(v, want, atol=1e-12)
    np.testing.assert_array_equal(x1, x)
    v2, x2 = -v, x.copy()
    assert KI.fire_mix(f, v2, x2, 0.01, 0.1, np.zeros(len(v2), dtype=np.bool_)) < 0
    np.testing.assert_allclose(x2, x + 0.005 * v, atol=1e-15)  # back along -v2, half a step
    assert np.all(v2 == 0.0)
    # a vertex in contact with the body is left out of the power (the contact response, not the
    # forces, moved it): here the first one's swing back alone no longer stops the cloth
    v3 = np.array([[-0.5, 0.0, 0.0], [0.0, 0.1, 0.0]])
    assert KI.fire_mix(f, v3.copy(), x.copy(), 0.01, 0.1, np.zeros(2, dtype=np.bool_)) < 0
    assert KI.fire_mix(f, v3, x.copy(), 0.01, 0.1, np.array([True, False])) == pytest.approx(0.2)
    assert np.any(v3 != 0.0)


def test_fire_mix_free_leaves_the_free_vertices_to_the_solver():
    """fire_mix_free: the vertices not free get fire_mix over themselves alone (their power, their
    mix or stop); the free ones keep their velocity and position (cloth let fall: drape's stand_out)."""
    f = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, -9.8, 0.0]])
    v = np.array([[0.5, 0.5, 0.0], [0.0, 0.0, 1.0], [0.3, -2.0, 0.0]])
    x = np.array([[0.0, 1.0, 0.0], [0.5, 1.0, 0.2], [0.0, 0.5, 0.3]])
    free = np.array([False, False, True])
    none = np.zeros(3, dtype=np.bool_)
    held = v[:2].copy()
    want = 0.9 * held + 0.1 * np.linalg.norm(held) * f[:2] / np.linalg.norm(f[:2])
    v1, x1 = v.copy(), x.copy()
    assert KI.fire_mix_free(f, v1, x1, 0.01, 0.1, none, free) == pytest.approx(0.5)  # (the free one's power left out)
    np.testing.assert_allclose(v1[:2], want, atol=1e-12)
    np.testing.assert_array_equal(v1[2], v[2])
    v2, x2 = v.copy(), x.copy()
    v2[:2] *= -1
    assert KI.fire_mix_free(f, v2, x2, 0.01, 0.1, none, free) < 0
    assert np.all(v2[:2] == 0.0) and np.all(v2[2] == v[2]) and np.all(x2[2] == x[2])
    np.testing.assert_allclose(x2[:2], x[:2] - 0.005 * (-v[:2]), atol=1e-15)



def test_the_guard_takes_away_the_velocity_that_would_stretch_its_springs_again():
    """inelastic_guard: a vertex the strain guard moved keeps its velocity along and across its
    move, but loses the part pointing back against it; vertices the guard left alone keep theirs."""
    x0 = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    x = x0.copy()
    x[0] += [0.001, 0.0, 0.0]  # moved +x
    x[1] += [0.0, 0.002, 0.0]  # moved +y
    v = np.array([[-0.5, 0.3, 0.0], [0.2, 0.4, -0.1], [-1.0, -1.0, 0.0]])
    assert KS.inelastic_guard(x, x0, v) == 1
    np.testing.assert_allclose(v[0], [0.0, 0.3, 0.0], atol=1e-12)  # the part against the move is gone
    np.testing.assert_allclose(v[1], [0.2, 0.4, -0.1])  # moving with its move: kept
    np.testing.assert_allclose(v[2], [-1.0, -1.0, 0.0])  # not moved: kept

@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan")])
def test_model_refuses_bad_spring_damping(garment, bad):
    with pytest.raises(InputError, match="spring damping"):
        _model(garment, params=replace(ClothParams(), spring_damping=bad))


def test_gravity_vector_is_y_down():
    np.testing.assert_allclose(GRAVITY, [0.0, -9.81, 0.0])


# --- velocity modification kernel ----------------------------------------------------------------------

def _two_points(stretch=1.2, v=((-1.0, 0.3, 0.0), (1.0, -0.2, 0.5))):
    x = np.array([[0.0, 0.0, 0.0], [stretch, 0.0, 0.0]])
    return x, np.array(v, dtype=np.float64)


def _vm(x, v, mode, threshold=0.1, recover=1e12, active=True, body_v=None):
    springs = np.array([[0, 1]], dtype=np.int32)
    rest = np.array([1.0])
    work = np.zeros(1, dtype=np.int32)
    body_v = np.zeros((2, 3)) if body_v is None else np.asarray(body_v, np.float64)
    return KS.modify_velocities(x, v, springs, rest, np.array([active]), threshold, KS.VM_MODES[mode],
                               np.array([0.0, -9.81, 0.0]), 1e-4, body_v, 4, work, np.zeros((1, 4)),
                               np.zeros((1, 2), np.int32), recover)


@pytest.mark.parametrize("recover", [1e12, StepConfig().recover])
def test_average_mode(recover):
    x, v = _two_points()
    v0 = v.copy()
    n = _vm(x, v, "average", recover=recover)
    assert n == 1
    rel = v[1, 0] - v[0, 0]  # along the spring (x axis)
    assert rel <= 1e-12
    if recover > 1:
        assert rel == pytest.approx(0.0, abs=1e-12)  # eq. 5: both set to their average
    np.testing.assert_allclose(v.mean(axis=0), v0.mean(axis=0), atol=1e-12)  # momentum unchanged
    np.testing.assert_allclose(v[:, 1:], v0[:, 1:])  # across the spring: untouched


@pytest.mark.parametrize("recover", [1e12, StepConfig().recover])
def test_zero_mode(recover):
    x, v = _two_points()
    v0 = v.copy()
    _vm(x, v, "zero", recover=recover)
    assert v[1, 0] - v[0, 0] <= 1e-12
    if recover > 1:
        np.testing.assert_allclose(v[:, 0], 0.0, atol=1e-12)  # seed 003: both set to zero
    else:  # zero plus the recovery closing speed: a moves toward b, b toward a
        assert v[0, 0] >= 0 and v[1, 0] <= 0
    np.testing.assert_allclose(v[:, 1:], v0[:, 1:])


@pytest.mark.parametrize("mode", ["average", "zero", "directional"])
def test_vm_leaves_unstretched_or_closing_or_inactive_springs_alone(mode):
    x, v = _two_points(stretch=1.05)  # within the 10 % threshold
    v0 = v.copy()
    assert _vm(x, v, mode) == 0
    np.testing.assert_array_equal(v, v0)
    x, v = _two_points(v=((1.0, 0, 0), (-1.0, 0, 0)))  # stretched but already closing
    v0 = v.copy()
    _vm(x, v, mode)
    np.testing.assert_array_equal(v, v0)
    x, v = _two_points()
    v0 = v.copy()
    assert _vm(x, v, mode, active=False) == 0
    np.testing.assert_array_equal(v, v0)


def test_directional_mode_rear_point_catches_up():
    # both ends dragged by a body moving +z; the spring lies along z, b ahead along v_dir
    x = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.2]])
    v = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 3.0]])  # b runs ahead: stretching
    _vm(x, v, "directional", body_v=[[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    # the rear point (a) takes the front point's speed; the front is unchanged
    np.testing.assert_allclose(v[1], [0.0, 0.0, 3.0])
    np.testing.assert_allclose(v[0], [0.0, 0.0, 3.0])


def test_directional_mode_free_spring_averages():
    # a falling vertical spring, no body: v_dir = g dt; the catch-up rule would hand the lower
    # end's speed up the chain (engine.cloth.kernels.DIR_MIN_OBJECT_SPEED): eq. 5 instead
    x = np.array([[0.0, 0.0, 0.0], [0.0, -1.2, 0.0]])
    v = np.array([[0.0, -1.0, 0.0], [0.0, -3.0, 0.0]])
    _vm(x, v, "directional")
    np.testing.assert_allclose(v, [[0.0, -2.0, 0.0], [0.0, -2.0, 0.0]])


@pytest.mark.parametrize("dragged", [0, 1])
def test_directional_mode_free_end_follows_the_dragged_one(dragged):
    # one end held by a body moving +z at 1 m/s, the other free and lagging: whichever is the
    # rear along v_dir, the free end takes the dragged end's speed along the spring
    x = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.2]])
    v = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    free = 1 - dragged
    v[free, 2] = 3.0 if free == 1 else -1.0  # moving away from the dragged end
    body_v = np.zeros((2, 3))
    body_v[dragged, 2] = 1.0
    _vm(x, v, "directional", body_v=body_v)
    np.testing.assert_allclose(v[dragged], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(v[free], [0.0, 0.0, 1.0])


# --- welds ---------------------------------------------------------------------------------------------

def test_merge_map_chains_and_keeps_others():
    new = merge_map(6, np.array([[0, 1], [1, 2], [4, 5]]))
    assert new[0] == new[1] == new[2]
    assert new[4] == new[5]
    assert len({new[0], new[3], new[4]}) == 3
    assert sorted(set(new.tolist())) == [0, 1, 2]  # compact numbering
    np.testing.assert_array_equal(merge_map(3, np.zeros((0, 2), np.int64)), [0, 1, 2])
    # order of pairs and direction within a pair do not matter
    a = merge_map(5, np.array([[2, 1], [3, 2]]))
    assert a[1] == a[2] == a[3] and a[0] != a[1] and a[4] != a[1]


@pytest.mark.parametrize("masses", ["equal", "unequal"])
def test_pull_seams_conserves_momentum_and_closes(masses):
    rng = np.random.default_rng(3)
    n = 8
    x = rng.normal(size=(n, 3))
    v = rng.normal(size=(n, 3)) * 0.1
    mass = np.full(n, 0.01) if masses == "equal" else rng.uniform(0.005, 0.02, n)
    pairs = np.array([[0, 1], [2, 3], [4, 5], [6, 7]], dtype=np.int32)
    welded = np.zeros(len(pairs), dtype=np.bool_)
    p0 = (mass[:, None] * v).sum(0)
    v0 = v.copy()
    tau, vmax = 0.5, 1.0
    pull_seams(x, v, mass, pairs, welded, tau, vmax, np.zeros(n, np.bool_), np.zeros((n, 3)),
               np.zeros((1, 3)), np.zeros(len(pairs), np.bool_))
    np.testing.assert_allclose((mass[:, None] * v).sum(0), p0, atol=1e-12)
    for a, b in pairs:
        d = x[b] - x[a]
        gap = np.linalg.norm(d)
        closing = (v[a] - v[b]) @ d / gap
        assert closing == pytest.approx(min(gap / tau, vmax), rel=1e-9)
    # a welded pair is left to hold_welds
    v = v0.copy()
    pull_seams(x, v, mass, pairs, np.ones(len(pairs), np.bool_), tau, vmax, np.zeros(n, np.bool_), np.zeros((n, 3)),
               np.zeros((1, 3)), np.zeros(len(pairs), np.bool_))
    np.testing.assert_array_equal(v, v0)


def test_a_pair_with_a_meeting_point_is_pulled_to_it_not_to_each_other():
    x = np.array([[0.0, 0.0, 0.1], [0.0, 0.0, -0.1]])
    v = np.zeros((2, 3))
    mass = np.full(2, 0.01)
    pairs = np.array([[0, 1]], dtype=np.int32)
    meet = np.array([[-0.1, 0.0, 0.0]])
    tau, vmax = 0.5, 1.0
    pull_seams(x, v, mass, pairs, np.zeros(1, np.bool_), tau, vmax, np.zeros(2, np.bool_), np.zeros((2, 3)),
               meet, np.ones(1, np.bool_))
    for end in (0, 1):
        d = meet[0] - x[end]
        np.testing.assert_allclose(v[end], d / tau, atol=1e-12)  # straight at the meeting point, gap / tau
    # a seam end lying on the body is not pulled into it: the inward part of its pull is dropped
    v = np.zeros((2, 3))
    contact = np.array([True, False])
    normal = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])  # the body's surface faces +x at vertex 0
    pull_seams(x, v, mass, pairs, np.zeros(1, np.bool_), tau, vmax, contact, normal, meet, np.ones(1, np.bool_))
    assert v[0, 0] == pytest.approx(0.0, abs=1e-12) and v[0, 2] < 0.0
    assert v[1, 0] < 0.0


# --- fabrics -------------------------------------------------------------------------------------------

def test_unknown_fabric_lists_the_fabrics():
    with pytest.raises(InputError) as ei:
        get_fabric("wool")
    msg = str(ei.value)
    assert "wool" in msg
    for name in ("cotton", "denim", "silk", "jersey"):
        assert name in msg


def test_fabrics_are_physical():
    for f in FABRICS.values():
        assert 0.03 < f.density < 0.6  # kg/m^2: 30 .. 600 g/m^2
        assert f.stretch > 0 and f.shear > 0 and f.bending > 0
        assert 0 < f.friction < 1 and 0 < f.strain_threshold < 1.0  # (a rib stretches to about twice its width)
    assert FABRICS["denim"].density > FABRICS["cotton"].density > FABRICS["silk"].density
    assert FABRICS["jersey"].strain_threshold > FABRICS["cotton"].strain_threshold
    # an elastane knit: easier to stretch than jersey, worn further stretched, heavier
    knit = FABRICS["stretch_knit"]
    assert knit.stretch < FABRICS["jersey"].stretch and knit.strain_threshold > FABRICS["jersey"].strain_threshold
    assert knit.density > FABRICS["jersey"].density
    # a rib (cuffs, bands): stretches round further still, and only round
    rib = FABRICS["rib_knit"]
    assert rib.strain_threshold > knit.strain_threshold and rib.stretch < knit.stretch and rib.crosswise
    assert not any(f.crosswise for f in FABRICS.values() if f is not rib)


def test_stale_contacts_carry_the_last_answer_forward():
    # three points answered at the query: in the band (depth 2 mm, normal +z), clear 10 mm
    # from the band, inside (depth 4 mm, normal +x)
    q_pts = np.zeros((3, 3))
    q_st = np.array([1, 0, 2], np.int8)
    q_n = np.array([[0, 0, 1.0], [0, 0, 1.0], [1.0, 0, 0]])
    q_d = np.array([0.002, -0.01, 0.004])
    st, d = np.zeros(3, np.int8), np.zeros(3)
    none = np.zeros(0, np.int64)
    # point 0 moved 3 mm out along its normal (leaves the band), point 2 moved 1 mm deeper
    pts = q_pts + np.array([[0, 0, 0.003], [0.0005, 0, 0], [-0.001, 0, 0]])
    assert KR.stale_contacts(pts, q_pts, q_pts, q_st, q_n, q_d, st, d, 0.004, 0.0005, none, False) == 0
    assert st.tolist() == [0, 0, 2]
    assert d[0] == pytest.approx(-0.001) and d[2] == pytest.approx(0.005)
    # stale: a point moved more than `reach`, or the clear one moved past its distance + slack
    assert KR.stale_contacts(pts, q_pts, q_pts, q_st, q_n, q_d, st, d, 0.002, 0.0005, none, False) == -1
    pts[1] = [0.0, 0.0, -0.011]
    assert KR.stale_contacts(pts, q_pts, q_pts, q_st, q_n, q_d, st, d, 0.1, 0.0005, none, False) == -1
    # ... unless the collider can answer that point alone: then it is listed, the rest carries
    rows = np.zeros(3, np.int64)
    assert KR.stale_contacts(pts, q_pts, q_pts, q_st, q_n, q_d, st, d, 0.1, 0.0005, rows, False) == 1
    assert rows[0] == 1
    pts[1] = [0.0, 0.0, -0.0104]
    assert KR.stale_contacts(pts, q_pts, q_pts, q_st, q_n, q_d, st, d, 0.1, 0.0005, none, False) == 0


def test_carried_map_depth_follows_the_slope():
    """The maps measure depth along z: on a surface at 60 degrees from the view (n_z = 0.5) a
    point that moves 1 mm out along the normal leaves 2 mm of map depth behind; an answer from
    the side layer (n_z = 0) or an object-space collider is a distance (1 mm)."""
    n = np.array([[np.sqrt(0.75), 0.0, 0.5], [1.0, 0.0, 0.0]])
    q_pts = np.zeros((2, 3))
    pts = q_pts + 0.001 * n
    q_st, q_d = np.array([1, 1], np.int8), np.array([0.004, 0.004])
    st, d = np.zeros(2, np.int8), np.zeros(2)
    none = np.zeros(0, np.int64)
    KR.stale_contacts(pts, q_pts, q_pts, q_st, n, q_d, st, d, 0.01, 0.0005, none, True)
    assert d.tolist() == pytest.approx([0.002, 0.003])
    KR.stale_contacts(pts, q_pts, q_pts, q_st, n, q_d, st, d, 0.01, 0.0005, none, False)
    assert d.tolist() == pytest.approx([0.003, 0.003])


def test_rows_to_ask_and_keep_rows():
    """At a new query only the contacts and the clear points that may have reached the band are
    asked; their answers replace the kept ones, the others stay as they were."""
    q_pts = np.zeros((4, 3))
    q_st = np.array([1, 0, 0, 0], np.int8)
    q_d = np.array([0.001, -0.01, -0.0005, -np.inf])  # contact; 10 mm, 0.5 mm clear; no map
    pts = q_pts + np.array([[0, 0, 0.0001], [0.0002, 0, 0], [0.0006, 0, 0], [0.0003, 0, 0]])
    rows = np.zeros(4, np.int64)
    k = KR.rows_to_ask(pts, q_pts, q_st, q_d, 0.001, 0.0, rows)
    assert rows[:k].tolist() == [0, 2]
    pts[3] = [0.002, 0, 0]  # moved past `reach`: asked even with no map under it
    k = KR.rows_to_ask(pts, q_pts, q_st, q_d, 0.001, 0.0, rows)
    assert rows[:k].tolist() == [0, 2, 3]
    status = np.array([2, 9, 1, 0], np.int8)
    normal = np.arange(12.0).reshape(4, 3)
    depth = np.array([0.006, 9.0, 0.001, -0.02])
    q_n, q_bv = np.zeros((4, 3)), np.zeros((4, 3))
    c_st, c_d = np.zeros(4, np.int8), np.zeros(4)
    KR.keep_rows(rows, k, pts, status, normal, normal + 1, depth, q_pts, q_st, q_n, q_bv, q_d, c_st, c_d)
    assert q_st.tolist() == c_st.tolist() == [2, 0, 1, 0]
    assert q_d.tolist() == [0.006, -0.01, 0.001, -0.02]
    assert c_d.tolist() == [0.006, 0.0, 0.001, -0.02]  # row 1 was not asked: left as it was
    assert np.array_equal(q_pts[[0, 2, 3]], pts[[0, 2, 3]]) and np.all(q_pts[1] == 0)
    assert np.array_equal(q_n[[0, 2, 3]], normal[[0, 2, 3]]) and np.all(q_n[1] == 0)
    assert np.array_equal(q_bv[[0, 2, 3]], normal[[0, 2, 3]] + 1)


class _CountingCollider(Collider):
    """A flat floor at y = 0 (status/normal/depth like the maps), counting its queries."""

    def __init__(self):
        self.calls, self.version = 0, 0

    def query(self, p):
        self.calls += 1
        tol = 0.005
        depth = tol - p[:, 1]
        st = np.where(depth > tol, 2, np.where(depth > 0, 1, 0)).astype(np.int8)
        n = np.zeros_like(p)
        n[:, 1] = 1.0
        return st, n, np.zeros_like(p), depth


def test_solver_requeries_when_the_body_moves_or_points_travel(garment):
    m = _model(garment)
    x = garment.positions.copy()
    x[:, 1] += 0.5 - x[:, 1].min()  # unstretched, at rest, far above the floor: answers are reused
    s = ClothSolver(m, _CountingCollider(), StepConfig(requery_every=8, requery_move=0.001), gravity=np.zeros(3))
    st = ClothState(x, np.zeros_like(x))
    for _ in range(16):
        s.step(st)
    assert s.collider.calls == 2
    s.collider.version += 1  # the body moved: ask again at once
    s.step(st)
    assert s.collider.calls == 3
    st.v[:] = [0.0, -1.0, 0.0]  # 1 m/s: a millimetre in a few steps -> asked more often
    calls = s.collider.calls
    for _ in range(16):
        s.step(st)
    travelled = 16 * m.dt_bound * 1.0  # metres each point moved in these steps
    assert int(travelled / 0.001) <= s.collider.calls - calls <= int(travelled / 0.001) + 1 < 8
    # a clear point heading for the floor is asked again before it gets 0.5 mm into the band,
    # even when `requery_move` alone would wait (1 cm here)
    s2 = ClothSolver(m, _CountingCollider(), StepConfig(requery_every=8, requery_move=0.01), gravity=np.zeros(3))
    x2 = garment.positions.copy()
    x2[:, 1] += 0.0055 - x2[:, 1].min()  # 0.5 mm above the band
    st = ClothState(x2, np.zeros_like(x2))
    st.v[:] = [0.0, -2.0, 0.0]  # 0.34 mm a step: past 0.5 + 0.5 mm by the 3rd step
    for _ in range(4):
        s2.step(st)
    assert s2.collider.calls >= 2


class _RowsCollider(_CountingCollider):
    """The floor, able to answer some points alone (as MapCollider.query_rows); counts them."""

    answers_rows = True

    def __init__(self):
        super().__init__()
        self.asked = 0

    def query(self, p):
        self.asked += len(p)
        return super().query(p)

    def query_rows(self, p, rows, k):
        self.asked += k
        r = rows[:k]
        st, n, bv, d = super().query(p[r])
        out = [np.zeros(len(p), np.int8), np.zeros_like(p), np.zeros_like(p), np.zeros(len(p))]
        for o, a in zip(out, (st, n, bv, d)):
            o[r] = a
        return tuple(out)


def test_solver_asks_a_rows_collider_only_for_points_that_may_have_changed(garment):
    """A sheet hanging clear of the floor is asked once, however many steps pass; a sheet lying
    in the floor's band is asked again only for its contacts (every `requery_every` steps), and
    the carried answers are those a fresh query gives."""
    m = _model(garment)
    cfg = StepConfig(requery_every=8, requery_move=0.001)
    n_pts = m.n + len(m.quads) + len(m.tris)
    x = garment.positions.copy()
    x[:, 1] += 0.5 - x[:, 1].min()
    s = ClothSolver(m, _RowsCollider(), cfg, gravity=np.zeros(3))
    st = ClothState(x, np.zeros_like(x))
    for _ in range(40):
        s.step(st)
    assert s.collider.asked == n_pts  # the first query only
    # tilted (rotated, not stretched) so that about half of it lies in the floor's band: the
    # contacts are asked again every 8 steps, the clear half not at all
    p = garment.positions  # the square lies in the xy plane: lay it on the floor (xz), tilted
    a = np.arcsin(0.01)
    x2 = np.stack([p[:, 0] * np.cos(a), 0.004 + p[:, 0] * np.sin(a), p[:, 1]], axis=1)
    s2 = ClothSolver(m, _RowsCollider(), cfg, gravity=np.zeros(3))
    st2 = ClothState(x2, np.zeros_like(x2))
    s2.step(st2)
    n_contact = int(np.count_nonzero(s2.answers._q[2]))  # the statuses of the first query
    assert 0.3 * n_pts < n_contact < 0.7 * n_pts
    for _ in range(16):
        s2.step(st2)
    # all at step 1, the contacts at steps 9 and 17, and the few clear points at the band's
    # edge whenever they move (asking everything would be 3 n_pts; measured: 26 of 257 points
    # with 2 contact rounds a step, fewer with 4)
    extra = s2.collider.asked - (n_pts + 2 * n_contact)
    assert 0 <= extra < 0.15 * n_pts
    fresh = _CountingCollider().query(s2.buf.points)
    carried = s2.answers.answer(s2.buf.points)
    assert np.array_equal(carried[0], fresh[0])
    assert np.allclose(carried[3], fresh[3], atol=1e-9)


def test_collisions_every_few_steps_still_stop_a_falling_sheet(garment):
    """collide_every=4: the floor is asked every 4th step with the points predicted 4 steps ahead,
    and the reaction force holds contacts in between -- a sheet thrown at the floor at 2 m/s stops
    in the tolerance band, as with a check every step; a bad setting is refused."""
    lowest = {}
    for every in (1, 4, 3.5):
        s = ClothSolver(_model(garment), _CountingCollider(), StepConfig(requery_every=1))
        control = Control(collide_every=every)
        x = garment.positions.copy()
        x[:, 1] += 0.02 - x[:, 1].min()
        st = ClothState(x, np.zeros_like(x))
        st.v[:] = [0.0, -2.0, 0.0]
        low = np.inf
        for _ in range(400):
            s.step(st, control)
            low = min(low, float(st.x[:, 1].min()))
        assert s.collider.calls == math.ceil(400 / every)  # (3.5: at steps 0, 4, 7, 11, 14, ...)
        lowest[every] = low
    assert min(lowest.values()) > 0.0, lowest  # never below the floor (the band is 0 .. 5 mm)
    assert abs(lowest[4] - lowest[1]) < 0.002 and abs(lowest[3.5] - lowest[1]) < 0.002


@pytest.mark.parametrize("every", [1, 3, 2.5, 3.77])
def test_checks_next_says_which_steps_ask_the_collider(garment, every):
    """ClothSolver.checks_next() before a step is True exactly when that step asks the collider
    (a walk puts its moving body at the step's time only then), whole or fractional spacing."""
    col = _CountingCollider()
    m = _model(garment)
    s = ClothSolver(m, col, StepConfig(requery_every=1))
    control = Control(collide_every=every)
    state = ClothState(garment.positions.copy() + (0.0, 0.3, 0.0), np.zeros_like(garment.positions))
    said, asked = [], []
    for _ in range(40):
        said.append(s.checks_next(control))
        before = col.calls
        s.step(state, control)
        asked.append(col.calls > before)
    assert said == asked
    assert 40 / every - 1 <= sum(asked) <= 40 / every + 1
    assert not ClothSolver(m).checks_next(control)  # no collider: never


def test_a_fractional_collide_every_checks_that_often_on_average(garment):
    """collide_every 2.5: checks at steps 0, 3, 5, 8, 10, ... (start + ceil(k x 2.5)), each
    predicting the points up to the next one; changing it starts a new schedule; a whole number
    checks where it divides the step count, as ever."""
    s = CheckSchedule()
    assert [s.now(2.5, i) for i in range(11)] == [3, 0, 0, 2, 0, 3, 0, 0, 2, 0, 3]
    assert s.now(1.5, 12) == 2  # a new schedule from here: 12, 14, 15, 17
    assert s.now(1.5, 13) == 0
    assert s.now(1.5, 14) == 1
    assert [s.now(4, i) for i in (16, 17, 20)] == [4, 0, 4]
    with pytest.raises(InputError, match="collide_every"):
        Tuning(collide_every=0).validate()


def test_weld_keeps_the_longer_rest_of_an_eased_seam():
    """Two one-quad panels stitched along edges of 10 and 11 mm: the welded seam spring takes the
    longer rest (the long side is eased in; the short rest would hold it stretched 10 % for good),
    masses add up, and springs that are not duplicated keep their own rest lengths."""
    uv = np.array([[0, 0], [0.010, 0], [0.010, 0.010], [0, 0.010],  # panel A: 10 mm top edge 3-2
                   [0, 0.02], [0.011, 0.02], [0.011, 0.03], [0, 0.03]])  # panel B: 11 mm bottom edge 4-5
    quads = np.array([[0, 1, 2, 3], [4, 5, 6, 7]], dtype=np.int32)
    panel = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    lattice = np.full((8, 2), -1)
    seams = np.array([[3, 4], [2, 5]], dtype=np.int32)
    m = build_model(uv, panel, lattice, quads, np.zeros((0, 3), np.int32), seams, get_fabric("cotton"), 0.01)
    vmap = merge_map(m.n, seams.astype(np.int64))
    w = weld_model(m, vmap)
    assert w.n == 6 and np.isclose(w.mass.sum(), m.mass.sum())
    rest = {tuple(sorted(p)): r for p, r in zip(w.springs.tolist(), w.rest)}
    assert np.isclose(rest[tuple(sorted((vmap[3], vmap[2])))], 0.011)
    assert np.isclose(rest[tuple(sorted((vmap[0], vmap[1])))], 0.010)  # A's bottom edge
    assert np.isclose(rest[tuple(sorted((vmap[6], vmap[7])))], 0.011)  # B's top edge
    assert len(rest) == len(w.springs)  # no duplicate springs left


def test_a_gathered_edge_carries_no_force_until_welded():
    """Two one-quad panels stitched along edges of 10 and 30 mm (a gather: the longer sewn into
    the shorter): while sewing, the long edge's spring pushes nothing back (k = 0) -- at its full
    rest it held a cuff 80-93 % stretched round a gathered sleeve end -- and the short edge's and
    every other spring keep theirs; welded, the seam's spring has the short rest and the short
    edge's stiffness."""
    uv = np.array([[0, 0], [0.010, 0], [0.010, 0.010], [0, 0.010],  # panel A: 10 mm top edge 3-2
                   [0, 0.02], [0.030, 0.02], [0.030, 0.03], [0, 0.03]])  # panel B: 30 mm bottom edge 4-5
    quads = np.array([[0, 1, 2, 3], [4, 5, 6, 7]], dtype=np.int32)
    panel, lattice = np.array([0, 0, 0, 0, 1, 1, 1, 1]), np.full((8, 2), -1)
    seams = np.array([[3, 4], [2, 5]], dtype=np.int32)
    fab = get_fabric("cotton")
    m = build_model(uv, panel, lattice, quads, np.zeros((0, 3), np.int32), seams, fab, 0.01)
    k = {tuple(sorted(p)): (kk, kind) for p, kk, kind in zip(m.springs.tolist(), m.stiffness, m.kind)}
    assert k[(4, 5)][0] == 0.0  # the gathered (long) edge
    assert k[(2, 3)][0] > 0 and k[(0, 1)][0] > 0 and k[(6, 7)][0] > 0
    assert sum(kk == 0.0 for kk, _ in k.values()) == 1
    vmap = merge_map(m.n, seams.astype(np.int64))
    w = weld_model(m, vmap)
    seam = [i for i, p in enumerate(w.springs.tolist()) if sorted(p) == sorted((vmap[2], vmap[3]))]
    assert len(seam) == 1 and np.isclose(w.rest[seam[0]], 0.010) and w.stiffness[seam[0]] == k[(2, 3)][0]
    assert (w.stiffness > 0).all()
    # edges that differ by no more than EASE are not a gather: both springs keep their stiffness
    uv2 = uv.copy()
    uv2[[5, 6], 0] = 0.0105
    m2 = build_model(uv2, panel, lattice, quads, np.zeros((0, 3), np.int32), seams, fab, 0.01)
    assert (m2.stiffness > 0).all()


def _two_strips(h: float = 0.01):
    """Two 1 x 2-quad panels side by side in the flat, A's right column stitched to B's left."""
    uv = np.array([[0, y] for y in (0, h, 2 * h)] + [[h, y] for y in (0, h, 2 * h)] +  # A: 0-2 left, 3-5 seam
                  [[5 * h, y] for y in (0, h, 2 * h)] + [[6 * h, y] for y in (0, h, 2 * h)], dtype=float)  # B
    quads = np.array([[0, 3, 4, 1], [1, 4, 5, 2], [6, 9, 10, 7], [7, 10, 11, 8]], dtype=np.int32)
    panel = np.repeat([0, 1], 6)
    lattice = np.full((12, 2), -1)
    seams = np.array([[3, 6], [4, 7], [5, 8]], dtype=np.int32)
    m = build_model(uv, panel, lattice, quads, np.zeros((0, 3), np.int32), seams, get_fabric("cotton"), h)
    return uv, m, seams


def test_a_part_in_another_fabric_is_held_at_its_own_limit():
    """build_model's panel_fabrics: B of the two strips sewn from stretch_knit on a cotton model --
    its springs take the knit's stiffness, its cloth the knit's weight, and the strain limit holds
    it at the knit's threshold (limit_rest x (1.40 / 1.05)); A keeps cotton's. Welding keeps each
    spring's allowance (a seam spring shared by both: the knit's, the seam stretching with the
    knit) and so does restiffening for the walk."""
    uv, cotton, seams = _two_strips()
    knit = get_fabric("stretch_knit")
    h = 0.01
    panel = np.repeat([0, 1], 6)
    lattice = np.full((12, 2), -1)
    quads = np.array([[0, 3, 4, 1], [1, 4, 5, 2], [6, 9, 10, 7], [7, 10, 11, 8]], dtype=np.int32)
    m = build_model(uv, panel, lattice, quads, np.zeros((0, 3), np.int32), seams, get_fabric("cotton"), h,
                    panel_fabrics={1: knit})
    on_b = panel[m.springs[:, 0]] == 1
    ratio = (1.0 + knit.strain_threshold) / (1.0 + get_fabric("cotton").strain_threshold)
    limited = m.kind != FLEXION
    assert np.allclose(m.allow[on_b & limited], ratio) and np.allclose(m.allow[~on_b], 1.0)
    assert np.allclose(m.limit_rest[on_b & limited], m.rest[on_b & limited] * ratio)
    assert np.allclose(m.limit_rest[~on_b], cotton.limit_rest[~on_b])
    structural = m.kind == STRUCTURAL
    assert np.allclose(m.stiffness[on_b], spring_stiffness(m.kind, knit, m.params, h)[on_b])
    assert np.allclose(m.stiffness[~on_b & structural], cotton.stiffness[~on_b & structural])
    assert m.mass[panel == 1].sum() > 1.5 * cotton.mass[panel == 1].sum()  # (230 g/m^2 against 120)
    vmap = merge_map(m.n, seams.astype(np.int64))
    w = weld_model(m, vmap, uv)
    seam = {tuple(sorted((vmap[a], vmap[b]))) for a, b in ((3, 4), (4, 5))}
    for k, p in enumerate(np.sort(w.springs, axis=1).tolist()):
        if tuple(p) in seam:
            assert np.isclose(w.allow[k], ratio), (p, w.allow[k])
    assert len(w.allow) == len(w.springs)
    st = with_stiffness(w, 0.25)
    assert st.allow is w.allow and np.array_equal(st.limit_rest, w.limit_rest)


def test_a_rib_part_stretches_crosswise_at_its_own_springs():
    """Fabric.crosswise (rib_knit): a part sewn from a rib takes its own springs crosswise (along
    the panel's x, round the limb) and on the bias, far softer than the floor; lengthwise it keeps
    ClothParams.sag_as's floor (no softer for its weight than cotton), so it does not sag."""
    uv, cotton, seams = _two_strips()
    rib, h = get_fabric("rib_knit"), 0.01
    assert rib.crosswise and not get_fabric("stretch_knit").crosswise
    panel = np.repeat([0, 1], 6)
    quads = np.array([[0, 3, 4, 1], [1, 4, 5, 2], [6, 9, 10, 7], [7, 10, 11, 8]], dtype=np.int32)
    m = build_model(uv, panel, np.full((12, 2), -1), quads, np.zeros((0, 3), np.int32), seams,
                    get_fabric("cotton"), h, panel_fabrics={1: rib})
    on_b = panel[m.springs[:, 0]] == 1
    d = uv[m.springs[:, 1]] - uv[m.springs[:, 0]]
    along = (m.kind == STRUCTURAL) & (np.abs(d[:, 1]) > np.abs(d[:, 0]))
    across = (m.kind == STRUCTURAL) & ~along
    own = spring_stiffness(m.kind, rib, replace(m.params, sag_as=None), h)
    floor = spring_stiffness(m.kind, rib, m.params, h)
    assert (on_b & along).any() and (on_b & across).any()
    assert np.allclose(m.stiffness[on_b & across], own[on_b & across])
    assert np.allclose(m.stiffness[on_b & along], floor[on_b & along])
    assert np.allclose(m.stiffness[on_b & (m.kind == SHEAR)], own[on_b & (m.kind == SHEAR)])
    assert m.stiffness[on_b & across].max() < 0.1 * m.stiffness[on_b & along].min()
    assert np.allclose(m.stiffness[~on_b], cotton.stiffness[~on_b])  # (A, cotton, as it was)
    whole = build_model(uv, panel, np.full((12, 2), -1), quads, np.zeros((0, 3), np.int32), seams, rib, h)
    assert np.allclose(whole.stiffness[on_b], m.stiffness[on_b])  # (a garment all in rib: the same springs)


@pytest.mark.parametrize("name", ["jersey", "stretch_knit", "denim", "silk"])
def test_no_fabric_sags_more_than_cotton_for_its_weight(name):
    """ClothParams.sag_as: each fabric's stretch and shear springs are at least as stiff per unit
    weight as cotton's (a knit at stiffness_scale 0.03 alone sagged toward its threshold under its
    own weight); a fabric stiffer than that keeps its own; sag_as=None gives the plain scale."""
    cotton, fab = get_fabric("cotton"), get_fabric(name)
    kind = np.array([STRUCTURAL, SHEAR, FLEXION])
    p = ClothParams()
    k, kc = spring_stiffness(kind, fab, p, H), spring_stiffness(kind, cotton, p, H)
    assert np.all(k[:2] / fab.density >= kc[:2] / cotton.density * (1 - 1e-12))
    assert np.isclose(k[0], max(fab.stretch, cotton.stretch * fab.density / cotton.density) * p.stiffness_scale)
    assert np.isclose(k[2], fab.bending / H ** 2)
    plain = spring_stiffness(kind, fab, replace(p, sag_as=None), H)
    assert np.isclose(plain[0], fab.stretch * p.stiffness_scale) and np.isclose(plain[1], fab.shear * p.stiffness_scale)


def test_held_panels_names_the_part_held_at_its_limit():
    """engine.scene.drape.held_panels: of the two strips, B stretched 6 % (cotton's 5 % and past
    its guard) is held; A at rest is not. A square panel stretched 6 % all over is held, 3 % is
    not, and in stretch_knit (40 %) the same 6 % is nothing."""
    from types import SimpleNamespace

    from engine.scene.drape import held_panels

    uv, m, seams = _two_strips()
    g = SimpleNamespace(panel=np.repeat([0, 1], 6), panel_names=["A", "B"])
    x = np.zeros((m.n, 3))
    x[:, :2] = uv
    x[6:, :2] = uv[6] + (uv[6:] - uv[6]) * 1.06
    assert held_panels(g, m, x, None, m.fabric, 0.005) == ["B"]
    big = build_garment(square_spec(), h=H)
    m2 = build_model(big.uv, big.panel, big.lattice, big.quads, big.tris, big.seams, get_fabric("cotton"), H)
    g2 = SimpleNamespace(panel=big.panel, panel_names=big.panel_names)
    x2 = np.zeros((m2.n, 3))
    x2[:, :2] = big.uv * 1.06
    assert held_panels(g2, m2, x2, None, m2.fabric, 0.005) == ["square"]
    x2[:, :2] = big.uv * 1.03
    assert held_panels(g2, m2, x2, None, m2.fabric, 0.005) == []
    k2 = build_model(big.uv, big.panel, big.lattice, big.quads, big.tris, big.seams, get_fabric("cotton"), H,
                     panel_fabrics={0: get_fabric("stretch_knit")})
    x2[:, :2] = big.uv * 1.06
    assert held_panels(g2, k2, x2, None, k2.fabric, 0.005) == []


def test_welding_adds_flexion_springs_across_the_seam():
    """Each stitch pair gets a flexion spring from A's neighbour square to the seam to B's, resting
    at the two panels lying flat (2 h); without the flat uv there are none (a free hinge)."""
    uv, m, seams = _two_strips()
    vmap = merge_map(m.n, seams.astype(np.int64))
    plain, sewn = weld_model(m, vmap), weld_model(m, vmap, uv)
    assert len(sewn.springs) == len(plain.springs) + 3
    new = {tuple(sorted(p)): (r, k) for p, r, k in zip(sewn.springs[-3:].tolist(), sewn.rest[-3:], sewn.kind[-3:])}
    assert set(new) == {tuple(sorted((vmap[a], vmap[b]))) for a, b in ((0, 9), (1, 10), (2, 11))}
    assert all(np.isclose(r, 0.02) and k == FLEXION for r, k in new.values())


def test_a_sewn_seam_folded_flat_opens():
    """The two strips welded and folded 180 degrees at the seam (B lying on A, 2 mm above):
    with the seam's flexion springs the fold opens; without them it stays shut."""
    uv, m, seams = _two_strips()
    vmap = merge_map(m.n, seams.astype(np.int64))
    spread = {}
    for label, w in (("hinge", weld_model(m, vmap)), ("sewn", weld_model(m, vmap, uv))):
        x = np.zeros((w.n, 3))
        for i in range(m.n):  # A flat at z = 0; B folded back over it at z = 2 mm
            u = uv[i, 0] if i < 6 else 2 * 0.01 - (uv[i, 0] - 4 * 0.01)
            x[vmap[i]] = [u, uv[i, 1], 0.0 if i < 6 else 0.002 * (uv[i, 0] - 5 * 0.01) / 0.01]
        st = ClothState(x, np.zeros_like(x))
        s = ClothSolver(w, None, gravity=np.zeros(3))
        for _ in range(3000):
            s.step(st)
        assert np.isfinite(st.x).all()
        spread[label] = float(np.linalg.norm(st.x[vmap[0]] - st.x[vmap[9]]))  # 0 when shut, 2 h when flat
    assert spread["hinge"] < 0.005 and spread["sewn"] > 0.01, spread


def test_sharp_folds_counts_cloth_folded_back():
    """A flat sheet has none; folded back on itself along one row of edges, that row counts."""
    from engine.scene.tryon import sharp_folds

    n = 6
    g = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 2) * 0.01
    idx = np.arange(n * n).reshape(n, n)
    tris = np.concatenate([np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:]], -1).reshape(-1, 3),
                           np.stack([idx[:-1, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 3)])
    flat = np.c_[g, np.zeros(len(g))]
    assert sharp_folds(flat, tris)["count"] == 0
    assert sharp_folds(flat, tris)["edges"] == 3 * 25 - 2 * 5  # the interior edges of 5 x 5 squares
    folded = flat.copy()
    over = g[:, 0] > 0.025  # rows past x = 2.5 cm fold back over the rest, 1 mm above
    folded[over, 0] = 0.06 - g[over, 0]
    folded[over, 2] = 0.001
    assert sharp_folds(folded, tris)["count"] == n - 1  # the row of edges on the crease x = 3 cm


def test_mass_scaling_on_a_catalogue_dress_lengthens_the_step_for_little_mass():
    """The catalogue dress at 1.5 cm (sliver points on clipped outlines, stiff spring stars):
    mass scaling lifts at most 5.5 % of the points (5.0 % on default:female in M), adds under 1 %
    of the weight, and lengthens
    the eq. 4 step by over 10 % against the same model without it."""
    g, m = _catalogue_dress_model()
    fab = m.fabric
    lumped = lumped_mass(g.uv, g.quads, g.tris, fab.density)
    floored = np.maximum(lumped, MASS_FLOOR * np.median(lumped))
    k_at = np.bincount(m.springs[:, 0], m.stiffness, m.n) + np.bincount(m.springs[:, 1], m.stiffness, m.n)
    unscaled_dt = 0.4 * np.pi * np.sqrt(np.min(floored / k_at))
    assert (m.mass > floored * (1 + 1e-12)).mean() <= 0.055
    assert m.mass.sum() <= floored.sum() * 1.01
    assert m.dt_bound >= 1.1 * unscaled_dt


def _catalogue_dress_model():
    from engine.body.default import default_body
    from engine.garment.garment import spec_placement
    from engine.scene.garments import resolve_garment

    body = default_body("female")
    spec, place, name = resolve_garment("dress", body, "M")
    g = build_garment(spec, h=0.015, place=place or spec_placement(spec, body.to_world), source=name)
    m = build_model(g.uv, g.panel, g.lattice, g.quads, g.tris, g.seams, get_fabric("cotton"), 0.015)
    return g, m


def test_spring_runs_hold_every_spring_once():
    """The force pass's spring order (SpringRuns): a permutation of the model's springs, each run
    really (a0 + t, b0 + t), the runs first; on the catalogue dress most springs lie in runs
    (measured: 93 % of the welded dress's 25.5k)."""
    from engine.cloth.model import MIN_RUN, spring_runs

    _, m = _catalogue_dress_model()
    r = m.runs
    assert r is m.runs  # made once per model
    assert np.array_equal(np.sort(r.perm), np.arange(len(m.springs)))
    assert np.array_equal(r.springs, m.springs[r.perm])
    # the flexion springs are the slow group, after the others
    assert r.n_fast == np.count_nonzero(m.kind != FLEXION)
    assert np.all(m.kind[r.perm[:r.n_fast]] != FLEXION) and np.all(m.kind[r.perm[r.n_fast:]] == FLEXION)
    for runs, covered, n_in in ((r.runs[:r.r_fast], 0, r.n_run), (r.runs[r.r_fast:], r.n_fast, r.n_run_slow)):
        start = covered
        for first, a0, b0, length in runs:
            assert first == covered and length >= MIN_RUN
            t = np.arange(length)
            assert np.array_equal(r.springs[first:first + length], np.stack([a0 + t, b0 + t], axis=1))
            covered += length
        assert covered - start == n_in
    assert r.n_run + r.n_run_slow >= 0.85 * len(m.springs), (r.n_run + r.n_run_slow) / len(m.springs)
    assert r.fast.n_run == r.n_run and len(r.fast.perm) == r.n_fast and r.r_held == r.r_fast
    # the walk's layout: the shear springs' runs after the stretch springs' in the fast group
    h = spring_runs(m.springs, slow=m.kind == FLEXION, held=m.kind == SHEAR)
    assert np.array_equal(np.sort(h.perm), np.arange(len(m.springs)))
    assert np.array_equal(h.springs, m.springs[h.perm]) and h.n_fast == r.n_fast and 0 < h.r_held < h.r_fast
    in_runs = [np.arange(f, f + ln) for f, _, _, ln in h.runs[:h.r_fast]]
    own, held = np.concatenate(in_runs[:h.r_held]), np.concatenate(in_runs[h.r_held:])
    assert np.all(m.kind[h.perm[own]] == STRUCTURAL) and np.all(m.kind[h.perm[held]] == SHEAR)
    assert np.array_equal(np.concatenate([own, held]), np.arange(h.n_run))
    for first, a0, b0, length in h.runs:
        t = np.arange(length)
        assert np.array_equal(h.springs[first:first + length], np.stack([a0 + t, b0 + t], axis=1))
    assert np.array_equal(h.runs[h.r_fast:, 1:], r.runs[r.r_fast:, 1:]) and h.n_run_slow == r.n_run_slow
    # a scattered spring list has no runs and is all done one by one
    one = spring_runs(np.array([[0, 5], [3, 1], [7, 2]], np.int32))
    assert one.n_run == 0 and one.runs.shape == (0, 4) and sorted(one.perm) == [0, 1, 2]


def _force_pass(solver, x, v, damping, mu, dt, slow_due):
    return passes.eval_forces(solver.model, ClothState(x, v), solver.buf, passes.Forcing(GRAVITY, damping, mu), dt,
                              slow_due, 1e30)[0]


# (relative error of the forces: double; single precision, StepConfig.precision: 1.0e-5 of the
# largest force on this test's dress)
@pytest.mark.parametrize("single, held, tol", [(False, False, 1e-9), (True, False, 3e-5), (False, True, 1e-9),
                                               (True, True, 3e-5)])
def test_force_pass_matches_a_direct_sum(single, held, tol):
    """eval_forces_and_integrate on the catalogue dress, jiggled: forces (springs with damping
    along them, gravity, viscous damping, the reaction force on contacts with Coulomb friction),
    velocities after the step, and the listed over-long springs (in the model's order) against
    the same sums written with numpy one spring at a time -- in double precision, and in single
    (the walk's) to what single precision allows; with the shear springs held as the flexion
    springs are (StepConfig.hold_shear, the walk's) and without."""
    g, m = _catalogue_dress_model()
    rng = np.random.default_rng(3)
    x = g.positions + rng.normal(0, 0.002, g.positions.shape)
    v = rng.normal(0, 0.1, x.shape)
    solver = ClothSolver(m, config=StepConfig(precision="single" if single else "double", hold_shear=held))
    if single:
        assert solver.buf.fsoa.dtype == solver.buf.sprops.dtype == np.float32 and solver.buf.soa.dtype == np.float64
    if held:
        assert solver.buf.runs.r_held < solver.buf.runs.r_fast
    solver.buf.contact[:] = rng.random(m.n) < 0.3
    n = rng.normal(size=(m.n, 3))
    solver.buf.contact_n[:] = n / np.linalg.norm(n, axis=1, keepdims=True)
    dt, damping, mu = 1e-4, 0.02, 0.4
    v_after = v.copy()
    n_over = _force_pass(solver, x, v_after, damping, mu, dt, True)
    a, b = m.springs[:, 0], m.springs[:, 1]
    d = x[b] - x[a]
    length = np.linalg.norm(d, axis=1)
    rate = np.einsum("ij,ij->i", v[b] - v[a], d) / length
    c = (m.stiffness * (length - m.rest) + m.spring_c * rate) / length
    f = m.mass[:, None] * GRAVITY - damping * m.mass[:, None] * v
    np.add.at(f, a, c[:, None] * d)
    np.add.at(f, b, -c[:, None] * d)
    fn = np.einsum("ij,ij->i", f, solver.buf.contact_n)
    push = solver.buf.contact & (fn < 0)
    ft = f - fn[:, None] * solver.buf.contact_n
    scale = np.maximum(0.0, 1.0 - mu * -fn / np.linalg.norm(ft, axis=1))
    f = np.where(push[:, None], ft * scale[:, None], f)
    assert 0.1 < push.mean() < 0.2  # the reaction force was exercised
    scale_f = np.abs(f).max()
    assert np.abs(solver.f - f).max() <= tol * scale_f
    assert np.abs(v_after - (v + dt * f * m.inv_mass[:, None])).max() <= tol * dt * scale_f * m.inv_mass.max()
    limit = (1 + m.fabric.strain_threshold) * m.limit_rest
    over = np.flatnonzero((m.kind != FLEXION) & (length > limit))
    assert len(over) > 10
    listed = solver.buf.work[:n_over]
    if single:  # (a spring within single precision of its limit may go either way)
        near = np.abs(length - limit) <= 1e-6 * limit
        assert np.array_equal(np.setxor1d(listed, over), np.setxor1d(listed, over)[near[np.setxor1d(listed, over)]])
        assert np.all(np.diff(listed) > 0)  # in the model's order
        over = listed
    assert np.array_equal(listed, over)  # in the model's order (the velocity modification's)
    assert not solver.buf.listed.any()
    geo = solver.buf.geo[:n_over]
    assert np.allclose(geo[:, :3], d[listed] / length[listed, None], atol=10 * tol)
    assert np.allclose(geo[:, 3], length[listed] - limit[listed], atol=tol * m.rest.max())
    # a step where the flexion springs are not due: their forces are the ones evaluated above
    # (at x), the others' at the new positions
    x2 = x + rng.normal(0, 0.002, x.shape)
    solver.buf.contact[:] = False
    v2 = v.copy()
    n_over2 = _force_pass(solver, x2, v2, damping, mu, dt, False)
    flex = m.kind == FLEXION
    r = solver.buf.runs
    for first, _, _, length in r.runs[r.r_held:r.r_fast]:  # the held runs' springs (those outside runs are not held)
        flex[r.perm[first:first + length]] = True
    shear_held = np.count_nonzero(flex & (m.kind == SHEAR))
    assert shear_held > 0.8 * np.count_nonzero(m.kind == SHEAR) if held else shear_held == 0
    xs = np.where(flex[:, None], x[b] - x[a], x2[b] - x2[a])  # each spring's vector where it was evaluated
    ls = np.linalg.norm(xs, axis=1)
    cs = (m.stiffness * (ls - m.rest) + m.spring_c * np.einsum("ij,ij->i", v[b] - v[a], xs) / ls) / ls
    f2 = m.mass[:, None] * GRAVITY - damping * m.mass[:, None] * v
    np.add.at(f2, a, cs[:, None] * xs)
    np.add.at(f2, b, -cs[:, None] * xs)
    assert np.abs(solver.f - f2).max() <= tol * np.abs(f2).max()
    # (which differs from evaluating them at x2: the check above can tell)
    d2 = x2[b] - x2[a]
    l2 = np.linalg.norm(d2, axis=1)
    c2 = (m.stiffness * (l2 - m.rest) + m.spring_c * np.einsum("ij,ij->i", v[b] - v[a], d2) / l2) / l2
    change = np.where(flex[:, None], c2[:, None] * d2 - cs[:, None] * xs, 0.0)  # flexion at x2 instead of x
    fresh = f2.copy()
    np.add.at(fresh, a, change)
    np.add.at(fresh, b, -change)
    assert np.abs(solver.f - fresh).max() > 5 * np.abs(solver.f - f2).max()
    # every limited spring is listed where it is now, held or not (the held ones by their lengths alone)
    over2 = np.flatnonzero((m.kind != FLEXION) & (l2 > limit))
    assert (m.kind[over2] == SHEAR).sum() > 10
    listed2 = solver.buf.work[:n_over2]
    odd = np.setxor1d(listed2, over2)
    assert np.all(np.abs(l2[odd] - limit[odd]) <= (1e-6 if single else 1e-12) * limit[odd])
    assert np.all(np.diff(listed2) > 0)
    geo2 = solver.buf.geo[:n_over2]
    assert np.allclose(geo2[:, :3], d2[listed2] / l2[listed2, None], atol=10 * tol)
    assert np.allclose(geo2[:, 3], l2[listed2] - limit[listed2], atol=tol * m.rest.max())


def test_strain_guard_never_pulls_a_contact_into_the_body():
    """Provot's projection as the drape's strain guard (keep_out): an end touching the body (normal
    +y) keeps the outward part of its move only; without keep_out it is pulled below the surface."""
    def run(keep_out):
        x = np.array([[0.0, 0.0, 0.0], [0.1, -0.1, 0.0]])
        contact = np.array([True, False])
        normal = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
        n = KS.provot_positions(x, np.array([[0, 1]], np.int32), np.array([0.1]), np.array([True]), 0.0,
                               np.ones(2), 1, np.zeros(1, np.int32), keep_out, contact, normal)
        return n, x
    n, x = run(True)
    assert n == 1 and x[0, 1] == 0.0 and x[0, 0] > 0.0  # slid along the surface, not into it
    assert np.linalg.norm(x[1] - x[0]) < np.sqrt(2) * 0.1  # the spring still got shorter
    _, x = run(False)
    assert x[0, 1] < 0.0


def _stretched(garment, scale, noise):
    """A cloth stretched unevenly (positions scaled by `scale`, then moved by `noise` m at
    random), moving at random, a fifth of its points touching a body below it (normal +y)."""
    rng = np.random.default_rng(7)
    x0 = garment.positions * np.array(scale) + rng.normal(0.0, noise, garment.positions.shape)
    v0 = rng.normal(0.0, 0.3, x0.shape)
    contact = rng.random(len(x0)) < 0.2
    normal = np.zeros((len(x0), 3))
    normal[:, 1] = 1.0
    return x0, v0, contact, normal


def test_guard_positions_is_the_plain_guard_bit_for_bit(garment):
    """KS.guard_positions (a vector pass over the force pass's runs, then only the flagged
    springs and the springs next to what moved) gives exactly what provot_positions with
    keep_out followed by inelastic_guard gives: positions, velocities, the count and the list
    of long springs -- on a cloth stretched unevenly (many long springs next to each other, so
    projections make their neighbours long), some points touching a body -- and leaves its flag
    and point buffers clear for the next step."""
    m = _model(garment)
    x0, v0, contact, normal = _stretched(garment, [1.09, 1.0, 1.02], 0.0008)
    thr = m.fabric.strain_threshold + 0.02
    x1, v1, w1 = x0.copy(), v0.copy(), np.zeros(len(m.springs), np.int32)
    active = m.kind != FLEXION
    n1 = KS.provot_positions(x1, m.springs, m.limit_rest, active, thr, m.inv_mass, 6, w1, True, contact, normal, 0.0003)
    assert n1 > 50
    KS.inelastic_guard(x1, x0, v1)
    solver = ClothSolver(m)
    x2, v2, r = x0.copy(), v0.copy(), m.runs
    n2 = KS.guard_positions(x2, v2, m.springs, m.limit_rest, active, thr, m.inv_mass, 6, solver.buf.work, contact, normal,
                           0.0003, r.fast.perm, r.fast.runs, r.fast.springs, r.n_run, limits2(solver.model, thr)[solver.buf.runs.fast.perm], solver.buf.soa,
                           solver.buf.listed, solver.buf.listed_words, m.adj_ptr, m.adj_spring, solver.buf.x_guard,
                           solver.buf.saved, solver.buf.saved_list)
    assert n2 == n1
    np.testing.assert_array_equal(solver.buf.work[:n2], w1[:n1])
    np.testing.assert_array_equal(x2, x1)
    np.testing.assert_array_equal(v2, v1)
    assert not solver.buf.listed.any() and not solver.buf.saved.any()
    # nothing long: nothing moves
    x3, v3 = garment.positions.copy(), v0.copy()
    assert KS.guard_positions(x3, v3, m.springs, m.limit_rest, active, thr, m.inv_mass, 6, solver.buf.work, contact, normal,
                             0.0003, r.fast.perm, r.fast.runs, r.fast.springs, r.n_run, limits2(solver.model, thr)[solver.buf.runs.fast.perm], solver.buf.soa,
                             solver.buf.listed, solver.buf.listed_words, m.adj_ptr, m.adj_spring, solver.buf.x_guard,
                             solver.buf.saved, solver.buf.saved_list) == 0
    np.testing.assert_array_equal(x3, garment.positions)
    np.testing.assert_array_equal(v3, v0)


@pytest.mark.parametrize("sheared", [True, False])
def test_the_late_guard_finds_and_makes_what_guard_positions_does(garment, sheared):
    """StepConfig.late_guard: KS.guard_listed, flagging from the force pass's list of long
    springs (single precision lengths, held shear springs: the walk's solver), gives exactly
    what KS.guard_positions gives on the same positions and velocities -- on a cloth stretched
    unevenly, some points touching a body -- and then the listed springs whose ends moved are
    measured again (one no longer long is left alone: excess -1e30; so may be, in double, one
    whose end the guard looked at and did not move); the flag and point buffers are clear
    afterwards. (sheared: a cotton shearing to 30 degrees, its diagonals far from their limit;
    else every spring measured from its rest length, so that some listed springs end short of it.)"""
    m = _sheared_cotton(garment) if sheared else _model(garment)
    x0, v0, contact, normal = _stretched(garment, [1.05, 1.0, 1.0], 0.0005)
    solver = ClothSolver(m, config=StepConfig(strain_guard=0.02, precision="single", hold_shear=True,
                                              late_guard=True))
    solver.buf.contact[:], solver.buf.contact_n[:] = contact, normal
    state = ClothState(x0.copy(), v0.copy())
    n_over = solver._forces(state, passes.Forcing(GRAVITY, m.params.damping, m.fabric.friction), True)
    assert n_over > 50
    listed, geo_before = solver.buf.work[:n_over].copy(), solver.buf.geo[:n_over].copy()
    thr = m.fabric.strain_threshold + 0.02
    # the list comes with its springs' ends, and with those near the guard's length: every one
    # past it among them
    np.testing.assert_array_equal(solver.buf.ends[:n_over], m.springs[listed])
    near = solver.buf.near[:solver._n_near]
    assert 0 < len(near) < n_over and np.all(np.diff(near) > 0)
    ln = np.linalg.norm(x0[m.springs[listed, 1]] - x0[m.springs[listed, 0]], axis=1)
    assert set(np.flatnonzero(ln > (1.0 + thr) * m.limit_rest[listed])) <= set(near)
    assert np.all(ln[near] > (1.0 + m.fabric.strain_threshold + 0.0099) * m.limit_rest[listed[near]])
    x1, v1, w1 = state.x.copy(), state.v.copy(), np.zeros(len(m.springs), np.int32)
    plain = ClothSolver(m)
    r, pb = plain.buf.runs, plain.buf
    active = m.kind != FLEXION
    n1 = KS.guard_positions(x1, v1, m.springs, m.limit_rest, active, thr, m.inv_mass, 6, w1, contact, normal,
                           0.0003, r.fast.perm, r.fast.runs, r.fast.springs, r.n_run, limits2(m, thr)[r.fast.perm],
                           pb.soa, pb.listed, pb.listed_words, m.adj_ptr, m.adj_spring, pb.x_guard, pb.saved,
                           pb.saved_list)
    assert n1 > 10
    n2 = KS.guard_listed(state.x, state.v, m.springs, m.limit_rest, active, thr, m.inv_mass, 6, solver.buf.guard_work,
                        contact, normal, 0.0003, solver.buf.listed, solver.buf.listed_words, m.adj_ptr, m.adj_spring,
                        solver.buf.x_guard, solver.buf.saved, solver.buf.saved_list, solver.buf.work, solver.buf.geo,
                        solver.buf.ends, n_over, solver.buf.near, solver._n_near, limits2(solver.model, thr),
                        m.fabric.strain_threshold)
    assert n2 == n1
    np.testing.assert_array_equal(solver.buf.guard_work[:n2], w1[:n1])
    np.testing.assert_array_equal(state.x, x1)
    np.testing.assert_array_equal(state.v, v1)
    assert not solver.buf.listed.any() and not solver.buf.saved.any()
    # the list itself is kept; its geometry is new where an end moved
    np.testing.assert_array_equal(solver.buf.work[:n_over], listed)
    a, b = m.springs[listed, 0], m.springs[listed, 1]
    moved = np.any(x1[a] != x0[a], axis=1) | np.any(x1[b] != x0[b], axis=1)
    assert 10 < moved.sum() < n_over - 10
    geo = solver.buf.geo[:n_over]
    d = x1[b] - x1[a]
    length = np.linalg.norm(d, axis=1)
    excess = length - (1.0 + m.fabric.strain_threshold) * m.limit_rest[listed]
    fresh = np.where((excess > 0)[:, None], np.column_stack([d / length[:, None], excess]), -1e30)
    close = lambda g, h: np.all(np.abs(g - h) <= 1e-12, axis=1) | ((g[:, 3] == -1e30) & (h[:, 3] == -1e30))
    kept = np.all(geo == geo_before, axis=1)
    assert np.all(close(geo[moved], fresh[moved]))  # measured again ...
    assert np.all(kept[~moved] | close(geo[~moved], fresh[~moved]))  # (an end the sweep saved and did not move)
    assert np.allclose(geo[~moved], geo_before[~moved], rtol=0, atol=2e-5)  # (single against double)
    assert (moved & (excess > 0)).sum() > 3
    if sheared:
        return
    assert (moved & (excess <= 0)).sum() > 3
    # the velocity modification leaves a spring with that excess alone
    vv = state.v.copy()
    k = int(np.flatnonzero(moved & (excess <= 0))[0])
    s = listed[k]
    assert KS.modify_velocities(state.x, vv, m.springs[s:s + 1], m.rest[s:s + 1], active[s:s + 1],
                               m.fabric.strain_threshold, KS.VM_AVERAGE, GRAVITY, solver.dt, solver.buf.body_v, 3,
                               np.zeros(1, np.int32), geo[k:k + 1].copy(), m.springs[s:s + 1].copy(), 0.002, 1) == 1
    np.testing.assert_array_equal(vv, state.v)


def test_a_late_guarded_step_guards_what_it_integrated(garment):
    """With late_guard a step leaves its positions to the next step's force pass (pending);
    finish_guard guards them as guard_positions would, and nothing is pending after."""
    m = _model(garment)
    rng = np.random.default_rng(3)
    x0 = garment.positions * np.array([1.09, 1.0, 1.02]) + rng.normal(0.0, 0.0008, garment.positions.shape)
    solver = ClothSolver(m, config=StepConfig(strain_guard=0.02, late_guard=True))
    state = ClothState(x0.copy(), np.zeros_like(x0))
    solver.step(state)
    assert solver.guard_pending
    thr = m.fabric.strain_threshold + 0.02
    xs = state.x.copy()
    strain = lambda x: np.linalg.norm(x[m.springs[:, 1]] - x[m.springs[:, 0]], axis=1) / m.rest - 1.0
    assert strain(xs)[m.kind != FLEXION].max() > thr + 0.01
    solver.finish_guard(state)
    assert not solver.guard_pending and solver.guarded > 50
    assert strain(state.x)[m.kind != FLEXION].max() < strain(xs)[m.kind != FLEXION].max()
    solver.finish_guard(state)  # nothing pending: nothing moves
    x_after = state.x.copy()
    solver.finish_guard(state)
    np.testing.assert_array_equal(state.x, x_after)


def test_dropped_forces_change_nothing_else(garment):
    """StepConfig.keep_forces False (the walk's): the force pass no longer writes solver.f; the
    steps' positions and velocities are the same bit for bit."""
    m = _model(garment)
    x0, v0, _, _ = _stretched(garment, [1.05, 1.0, 1.0], 0.0005)
    out = []
    for drop in (False, True):
        solver = ClothSolver(m, config=StepConfig(keep_forces=not drop))
        state = ClothState(x0.copy(), v0.copy())
        for _ in range(5):
            solver.step(state)
        out.append((state.x, state.v, solver.f))
    np.testing.assert_array_equal(out[1][0], out[0][0])
    np.testing.assert_array_equal(out[1][1], out[0][1])
    assert np.abs(out[0][2]).max() > 0 and not out[1][2].any()


def test_strain_guard_shortens_a_spring_a_little_at_a_time():
    """The guard moves positions by at most max_move a spring a pass, so a spring stretched 3 mm
    past its limit (cloth torn over a body part) is brought back over several steps, not in one
    jump that compresses its neighbours; Provot's comparison mode (no limit) projects at once."""
    def run(max_move, passes):
        x = np.array([[0.0, 0.0, 0.0], [0.103, 0.0, 0.0]])
        args = (np.array([[0, 1]], np.int32), np.array([0.1]), np.array([True]), 0.0, np.ones(2), passes,
                np.zeros(1, np.int32), True, np.zeros(2, np.bool_), np.zeros((2, 3)))
        KS.provot_positions(x, *args, max_move) if max_move is not None else KS.provot_positions(x, *args)
        return x[1, 0] - x[0, 0]
    assert run(0.0003, 1) == pytest.approx(0.1027)
    assert run(0.0003, 4) == pytest.approx(0.1018)
    assert run(None, 1) == pytest.approx(0.1)  # the default: no limit


@pytest.mark.parametrize("mode", ["average", "directional"])
@pytest.mark.parametrize("rounds", [1, 2, 4])
def test_contact_rounds_match_the_kernels_in_turn(mode, rounds):
    """KC.contact_rounds (the solver's fused call) gives what modify_velocities, point_average and
    collision_response give called one after the other, round by round."""
    rng = np.random.default_rng(7)
    n, nq, nt, s = 300, 80, 20, 1200
    x = rng.normal(size=(n, 3))
    v0 = rng.normal(size=(n, 3))
    springs = rng.integers(0, n, (s, 2)).astype(np.int32)
    rest = np.linalg.norm(x[springs[:, 1]] - x[springs[:, 0]], axis=1) * rng.uniform(0.85, 1.1, s)
    active = np.ones(s, np.bool_)
    quads = rng.integers(0, n, (nq, 4)).astype(np.int32)
    tris = rng.integers(0, n, (nt, 3)).astype(np.int32)
    m = n + nq + nt
    status = rng.choice(np.array([0, 0, 0, 1, 2], np.int8), m)
    normal = rng.normal(size=(m, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    bvel = rng.normal(size=(m, 3)) * 0.1
    depth = rng.uniform(0.0, 0.01, m)
    g = np.array([0.0, -9.81, 0.0])
    mode_i = KS.VM_MODES[mode]
    body_prev = rng.normal(size=(n, 3)) * 0.1  # the body velocities of the previous step
    out = []
    for fused in (False, True):
        v = v0.copy()
        work, geo, ends = np.zeros(s, np.int32), np.zeros((s, 4)), np.zeros((s, 2), np.int32)
        body_v = body_prev.copy()
        contact, contact_n = np.zeros(n, np.bool_), np.zeros((n, 3))
        n_act = KS.modify_velocities(x, v, springs, rest, active, 0.05, mode_i, g, 1e-4, body_v, 6, work, geo,
                                    ends, 0.002)
        assert n_act > 0
        pv = np.zeros((m, 3))
        KC.point_average(v, quads, tris, pv)
        if fused:
            hits = KC.contact_rounds(v, ends, mode_i, g, 1e-4, 6, work, geo, 0.002, n_act,
                                    rounds, status, normal, bvel, depth, n, quads, tris, 0.005, 0.0, 0.4,
                                    contact, contact_n, body_v, np.zeros(m, np.int32), np.zeros(n, np.int32), 50.0)
        else:
            for r in range(rounds):
                if r > 0:
                    KS.modify_velocities(x, v, springs, rest, active, 0.05, mode_i, g, 1e-4, body_v, 6, work,
                                        geo, ends, 0.002, n_act)
                    KC.point_average(v, quads, tris, pv)
                hits = KC.collision_response(v, status, normal, bvel, depth, pv, n, quads, tris, 0.005, 0.0, 0.4,
                                            1e-4, contact, contact_n, body_v, 50.0)
        out.append((hits, v, contact, contact_n[contact], body_v))
    assert out[0][0] == out[1][0] == int((status != 0).sum())
    np.testing.assert_allclose(out[1][1], out[0][1], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out[1][2], out[0][2])
    np.testing.assert_array_equal(out[1][3], out[0][3])
    np.testing.assert_array_equal(out[1][4], out[0][4])


@pytest.mark.parametrize("drape_min", [0.2, 0.6])
def test_drape_ends_soon_after_the_cloth_settles(garment, drape_min):
    """A sheet lying still on the floor has settled from the start: the drape ends at the first
    test after `drape_min` with two full settle windows behind it (tested every fifth of a
    window), not at the next whole window (0.75 s for drape_min 0.6, with 0.25 s windows)."""
    from dataclasses import replace as dc_replace

    from engine.scene.drape import sew_and_drape
    from engine.scene.request import TryOnOptions
    from engine.scene.tuning import DrapeTuning

    flat = garment.positions.copy()
    flat[:, 0], flat[:, 1], flat[:, 2] = garment.uv[:, 0], 0.003, garment.uv[:, 1]  # in the floor's band
    g = dc_replace(garment, positions=flat)
    res = sew_and_drape(g, _CountingCollider(), TryOnOptions(),
                        Tuning(drape=DrapeTuning(min_time=drape_min, settle_time=0.25)))
    t = res.iterations["draping"] * res.model.dt_bound
    assert res.settled
    assert max(drape_min, 0.5) <= t <= max(drape_min, 0.5) + 0.05 + 1e-3, t


def test_hold_contacts_stops_only_the_inward_motion_of_contacts():
    """Between collision checks (walking checks every 4th step) a vertex in contact keeps the
    body's normal velocity at least: the part of its velocity, relative to the body's, that points
    into the body is removed; the tangential part, an outward motion and a free vertex are kept.
    (Without this the velocity modification pulled a tight dress's front 4 mm into the bust
    while walking, engine.cloth.solver.)"""
    n = np.array([[0.0, 0.0, 1.0]] * 4)
    body_v = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 0.5], [0.0, 0.0, 0.5], [0.0, 0.0, 0.5]])
    v = np.array([[0.3, 0.0, -1.0],   # in contact, moving in: keeps only its tangential part
                  [0.3, 0.0, 0.2],    # in contact, slower outward than the body: also pushed along
                  [0.3, 0.0, 0.9],    # in contact, leaving faster than the body: kept
                  [0.3, 0.0, -1.0]])  # not in contact: kept
    contact = np.array([True, True, True, False])
    out = v.copy()
    KC.hold_contacts(out, contact, n, body_v)
    np.testing.assert_allclose(out[0], [0.3, 0.0, 0.5])
    np.testing.assert_allclose(out[1], [0.3, 0.0, 0.5])
    np.testing.assert_allclose(out[2], v[2])
    np.testing.assert_allclose(out[3], v[3])
    # between checks the solver holds and integrates in one pass: the same, bit for bit
    rng = np.random.default_rng(5)
    x0, v0 = rng.normal(size=(500, 3)), rng.normal(size=(500, 3))
    cn = rng.normal(size=(500, 3))
    cn /= np.linalg.norm(cn, axis=1)[:, None]
    bv, touch = rng.normal(size=(500, 3)) * 0.3, rng.random(500) < 0.4
    x1, v1, x2, v2 = x0.copy(), v0.copy(), x0.copy(), v0.copy()
    KC.hold_contacts(v1, touch, cn, bv)
    KI.integrate_positions(x1, v1, 3e-4)
    KI.hold_and_integrate(x2, v2, 3e-4, touch, cn, bv)
    assert not np.array_equal(v1, v0)
    np.testing.assert_array_equal(v2, v1)
    np.testing.assert_array_equal(x2, x1)


def test_drape_progress_follows_the_drift_down_to_rest():
    """The drape's progress bar: 0 before the first drift is measured, rising as the drift falls
    (log scale, 1 m/s to the settle speed), full once the cloth is at rest."""
    from engine.scene.drape import _settle_fraction

    drifts = [np.inf, 2.0, 0.3, 0.05, 0.02, 0.006, 0.005, 0.001]
    f = [_settle_fraction(d, 0.005) for d in drifts]
    assert f[0] == 0.0 and f[1] == 0.0 and f[-1] == 1.0 and f[-2] == 1.0
    assert all(a <= b for a, b in zip(f, f[1:])) and 0.0 < f[3] < 1.0


@pytest.mark.parametrize("push_time", [0.02, 0.005])
def test_a_point_deep_in_the_band_moves_out_over_the_push_time(push_time):
    """A resting point in the inner half of the collision band gets an outward velocity of its
    depth past the band's middle over StepConfig.push_time (the walk's is shorter than the
    drape's: engine.scene.tuning.WalkTuning.step), at most MAX_PUSH; one in the outer half
    none."""
    tol = 0.005
    for depth, want in ((0.004, (0.004 - 0.5 * tol) / push_time), (0.002, 0.0), (0.5, KC.MAX_PUSH)):
        v = np.zeros((1, 3))
        contact, contact_n, vb = np.zeros(1, np.bool_), np.zeros((1, 3)), np.zeros((1, 3))
        hits = KC.collision_response(v, np.array([1], np.int8), np.array([[0.0, 1.0, 0.0]]), np.zeros((1, 3)),
                                    np.array([depth]), v.copy(), 1, np.zeros((0, 4), np.int32),
                                    np.zeros((0, 3), np.int32), tol, 0.0, 0.4, 1e-4, contact, contact_n, vb, 1.0 / push_time)
        assert hits == 1 and contact[0]
        np.testing.assert_allclose(v[0], [0.0, want, 0.0], rtol=1e-12, atol=1e-15)


def _sheared(garment, degrees: float) -> np.ndarray:
    """The flat square with its weft turned `degrees` toward the warp: every yarn keeps its
    length, only the angle between them changes (pure in-plane shear)."""
    g = math.radians(degrees)
    u, v = garment.uv[:, 0], garment.uv[:, 1]
    return np.stack([u + v * math.sin(g), 1.0 + v * math.cos(g), np.zeros_like(u)], axis=1)


def _sheared_cotton(garment):
    """A cotton that shears freely up to 30 degrees (Fabric.shear_lock; the presets hold 0)."""
    g = garment
    fab = replace(get_fabric("cotton"), shear_lock=30.0)
    return build_model(g.uv, g.panel, g.lattice, g.quads, g.tris, g.seams, fab, H)


def test_the_presets_hold_the_diagonals_at_the_stretch_threshold(model):
    """Every preset fabric (shear_lock 0) measures every spring from its rest length."""
    assert all(f.shear_lock == 0.0 for f in FABRICS.values())
    assert np.array_equal(model.limit_rest, model.rest)


def test_cotton_shears_freely_up_to_its_locking_angle(garment):
    """A woven fabric takes a curved shape by shearing (its yarns turn about their crossings)
    until the weave locks (Fabric.shear_lock, 30 degrees for cotton): sheared 20 degrees, no yarn
    is longer and the strain limit leaves the quads' diagonals alone, though they are 16 % long;
    sheared 50 degrees, they read as strained and the limit brings them back to their longest
    (the yarns at the threshold, the weave locked). A border triangle's slanted edge has no yarn
    beside it: it keeps the plain limit (bias 0)."""
    model = _sheared_cotton(garment)
    s, rest = model.springs, model.rest
    d = garment.uv[s[:, 1]] - garment.uv[s[:, 0]]
    yarn = (model.kind != FLEXION) & (np.abs(d).min(axis=1) < 1e-9)
    diag = model.kind == SHEAR
    assert yarn.sum() > 0 and diag.sum() > 0 and np.allclose(model.bias[diag], 1.0)
    assert np.all(model.bias[model.kind != SHEAR] == 0.0)
    assert (~yarn & (model.kind == STRUCTURAL)).any()  # (the border's slanted edges exist)
    thr = model.fabric.strain_threshold
    x = _sheared(garment, 20.0)
    length = np.linalg.norm(x[s[:, 1]] - x[s[:, 0]], axis=1)
    assert np.allclose(length[yarn], rest[yarn])
    assert (length[diag] / rest[diag]).max() == pytest.approx(math.sqrt(1 + math.sin(math.radians(20))), rel=1e-6)
    assert KS.max_strain(x, s, model.limit_rest, diag) <= 1e-9
    assert KS.max_strain(x, s, rest, diag) > thr  # (measured from its rest length, a diagonal was held at 5 %)
    before = x.copy()
    work = np.zeros(len(s), np.int32)
    args = (s, model.limit_rest, diag, thr, model.inv_mass, 8, work, False,
            np.zeros(model.n, np.bool_), np.zeros((model.n, 3)))
    assert KS.provot_positions(x, *args) == 0 and np.array_equal(x, before)
    x = _sheared(garment, 50.0)
    assert KS.max_strain(x, s, model.limit_rest, diag) > thr
    assert KS.provot_positions(x, *args) > 0
    for _ in range(50):  # (Provot's passes converge slowly where springs share ends)
        KS.provot_positions(x, *args)
    longest = (1 + thr) * math.sqrt(1 + math.sin(math.radians(model.fabric.shear_lock)))
    after = np.linalg.norm(x[s[diag, 1]] - x[s[diag, 0]], axis=1) / rest[diag]
    assert longest * 0.97 < after.max() < longest * 1.01


def test_the_shear_limit_survives_welding_and_restiffening(garment):
    """ClothModel.bias (which springs may shear) is carried through weld_model and with_stiffness;
    without it every spring would fall back to the plain limit, silently."""
    m = _sheared_cotton(garment)
    vmap = np.arange(m.n)
    vmap[1] = 0  # weld one pair of neighbours on the border
    vmap[vmap > 1] -= 1
    w = weld_model(m, vmap)
    assert w.bias is not None and len(w.bias) == len(w.springs)
    assert np.allclose(w.limit_rest[w.kind == SHEAR] / w.rest[w.kind == SHEAR],
                       math.sqrt(1 + math.sin(math.radians(m.fabric.shear_lock))))
    st = with_stiffness(w, 0.25)
    assert st.bias is w.bias and np.array_equal(st.limit_rest, w.limit_rest)


def test_a_sheet_dropped_on_the_ground_lies_on_it():
    """Control.floor: a square sheet falling from 10 cm above the ground ends lying on it (no
    vertex below it, all within a few mm of it), its horizontal drift held by friction; without
    a ground it falls on through that height. A vertex placed under the ground comes back up no
    faster than FLOOR_VMAX (a layout that put a hem under the feet is not flung up)."""
    from engine.cloth.config import Control
    from engine.cloth.passes import FLOOR_VMAX
    from engine.cloth.welds import rest_on_floor

    flat = square_spec(20.0)
    g = build_garment(flat, h=H)
    m = _model(g)
    p = g.positions  # (a vertical square: laid flat, tilted 3 degrees so that it lands edge first)
    x0 = np.column_stack([p[:, 0], 0.1 + 0.05 * (p[:, 0] - p[:, 0].min()), p[:, 1] - p[:, 1].mean()])
    for floor in (0.0, None):
        solver = ClothSolver(m, collider=None, config=StepConfig())
        state = ClothState(x0.copy(), np.tile([0.3, 0.0, 0.0], (len(x0), 1)))  # sliding sideways
        for _ in range(int(round(0.4 / solver.dt))):
            solver.step(state, Control(damping_scale=50.0, floor=floor))
        if floor is None:
            assert state.x[:, 1].max() < -0.1
        else:
            assert state.x[:, 1].min() >= -1e-9 and state.x[:, 1].max() < 0.005
            assert np.abs(state.v[:, 0]).max() < 0.05  # (friction stopped the slide)
    x = np.array([[0.0, -0.2, 0.0], [0.0, 0.5, 0.0]])
    v = np.zeros((2, 3))
    rest_on_floor(x, v, 0.0, 1e-4, 0.5, FLOOR_VMAX)
    assert v[0, 1] == pytest.approx(FLOOR_VMAX) and v[1, 1] == 0.0
