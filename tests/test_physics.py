"""The checks of docs/model.md §10, against analytic results."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numba import njit

from soft_snake_gym import Fluid, Integrator, Rod, SimConfig, Simulator, body_from_curvature
from soft_snake_gym.gaits import serpenoid, serpenoid_phase
from soft_snake_gym.physics import forces, geometry, layout

RNG_SEED = 1234


def bent_simulator(N: int, medium: str = "none", damping: float = 0.0, seed: int = RNG_SEED, **integ):
    """A simulator in a random bent, slightly stretched, moving state."""
    rng = np.random.default_rng(seed)
    sim = Simulator(
        SimConfig(
            rod=Rod(N=N, damping_bend=damping, damping_stretch=damping),
            medium=medium,
            integrator=Integrator(**integ),
        )
    )
    lbar = np.full(N - 1, 0.18)
    x = body_from_curvature(rng.normal(0, 0.4, N - 2), lbar * (1 + rng.normal(0, 0.02, N - 1)))
    sim.set_state(x=x, v=rng.normal(0, 0.3, (N, 2)), kbar=rng.normal(0, 0.3, N - 2), lbar=lbar)
    return sim


def energy_at(sim: Simulator, q: np.ndarray) -> float:
    geo = np.empty((2, q.size))
    geometry.edge_geometry(q, geo)
    return forces.elastic_energy(geo, sim.arrays.kbar, sim.arrays.lbar, sim.arrays.prm)


def total_energy(sim: Simulator) -> float:
    return sim.kinetic_energy() + sim.elastic_energy()


@pytest.mark.parametrize("N", [3, 10, 50])
def test_forces_are_minus_the_energy_gradient(N):
    sim = bent_simulator(N)
    F = sim.elastic_forces().ravel()
    q = sim.arrays.q.copy()
    grad = np.zeros_like(q)
    eps = 1e-6
    for i in range(q.size):
        qp, qm = q.copy(), q.copy()
        qp[i] += eps
        qm[i] -= eps
        grad[i] = (energy_at(sim, qp) - energy_at(sim, qm)) / (2 * eps)
    assert np.linalg.norm(F + grad) / np.linalg.norm(grad) < 1e-6


def _fd_jacobians(sim: Simulator, water: bool, eps: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    n = sim.arrays.q.size
    fd_x, fd_v = np.zeros((n, n)), np.zeros((n, n))
    for arr, fd in ((sim.arrays.q, fd_x), (sim.arrays.v, fd_v)):
        for i in range(n):
            old = arr[i]
            arr[i] = old + eps
            Fp = sim.force_jacobians(water)[0]
            arr[i] = old - eps
            Fm = sim.force_jacobians(water)[0]
            arr[i] = old
            fd[:, i] = (Fp - Fm) / (2 * eps)
    return fd_x, fd_v


@pytest.mark.parametrize("N", [3, 10])
@pytest.mark.parametrize("medium,damping", [("none", 0.0), ("none", 0.7), ("water", 0.0)])
def test_analytic_jacobians_match_finite_differences(N, medium, damping):
    sim = bent_simulator(N, medium=medium, damping=damping)
    water = medium == "water"
    _, dFdx, dFdv = sim.force_jacobians()
    fd_x, fd_v = _fd_jacobians(sim, water)
    assert np.abs(dFdv - fd_v).max() <= 1e-6 * max(np.abs(fd_v).max(), 1.0)
    assert np.abs(dFdx - fd_x).max() <= 1e-6 * np.abs(fd_x).max()
    if damping:  # the damping forces' position dependence on its own scale (stiffness hides it)
        sim.set_config(
            dataclasses.replace(
                sim.config, rod=dataclasses.replace(sim.config.rod, damping_bend=0.0, damping_stretch=0.0)
            )
        )
        _, dFdx_el, _ = sim.force_jacobians()
        fd_x_el, _ = _fd_jacobians(sim, water)
        damp_x, damp_fd_x = dFdx - dFdx_el, fd_x - fd_x_el
        assert np.abs(damp_fd_x).max() > 0.1
        assert np.abs(damp_x - damp_fd_x).max() <= 1e-5 * np.abs(damp_fd_x).max()
    if water:  # the drag part on its own scale, so the stiff elastic part cannot hide it
        _, dFdx_dry, dFdv_dry = sim.force_jacobians(water=False)
        fd_x_dry, fd_v_dry = _fd_jacobians(sim, False)
        drag_x, drag_fd_x = dFdx - dFdx_dry, fd_x - fd_x_dry
        drag_v, drag_fd_v = dFdv - dFdv_dry, fd_v - fd_v_dry
        assert np.abs(drag_fd_x).max() > 0.1 and np.abs(drag_fd_v).max() > 0.1
        assert np.abs(drag_x - drag_fd_x).max() <= 1e-5 * np.abs(drag_fd_x).max()
        assert np.abs(drag_v - drag_fd_v).max() <= 1e-6 * np.abs(drag_fd_v).max()


def test_internal_forces_sum_to_zero_and_exert_no_torque():
    sim = bent_simulator(10, damping=0.5)
    F = sim.elastic_forces()
    x = sim.x
    scale = np.abs(F).max()
    assert scale > 1.0
    assert np.abs(F.sum(axis=0)).max() < 1e-10 * scale
    torque = np.sum(x[:, 0] * F[:, 1] - x[:, 1] * F[:, 0])
    assert abs(torque) < 1e-10 * scale


def test_banded_added_mass_solve_matches_dense():
    sim = bent_simulator(12, medium="water")
    N = sim.N
    rng = np.random.default_rng(7)
    F = rng.normal(size=2 * N)
    a = np.zeros(2 * N)
    forces.solve_mass(
        sim.arrays.q,
        sim.arrays.prm,
        sim.arrays.buf[layout.B_M],
        F,
        a,
        sim.arrays.J,
        sim.arrays.ibuf[layout.I_PIV],
        True,
    )
    # dense M + M_A straight from docs/model.md §4
    Md = np.diag(np.repeat(sim.masses, 2))
    x = sim.x
    fl, rod = sim.config.fluid, sim.config.rod
    for i in range(N - 1):
        e = x[i + 1] - x[i]
        l = np.linalg.norm(e)
        n = np.array([-e[1], e[0]]) / l
        mu_n = fl.rho * np.pi * fl.C_A * rod.a**2 * l
        for r in (i, i + 1):
            for c in (i, i + 1):
                Md[2 * r : 2 * r + 2, 2 * c : 2 * c + 2] += mu_n / 4 * np.outer(n, n)
    expected = np.linalg.solve(Md, F)
    assert np.abs(a - expected).max() < 1e-12 * np.abs(expected).max()
    assert np.abs(a - F / np.repeat(sim.masses, 2)).max() > 1e-3  # added mass matters


def _free_vibration(
    method: str, h: float, substeps: int | None, T: float, N: int = 8, newton_tol: float = 1e-6
):
    sim = Simulator(
        SimConfig(
            rod=Rod(N=N, damping_bend=0.0),
            medium="none",
            integrator=Integrator(method=method, h=h, substeps=substeps, newton_tol=newton_tol),
        )
    )
    x0 = body_from_curvature(0.15 * np.sin(np.pi * np.arange(1, N - 1) / (N - 1)), sim.lbar)
    sim.reset(x=x0)
    energies, P, L = [total_energy(sim)], [], []
    for _ in range(round(T / h)):
        assert sim.step()
        energies.append(total_energy(sim))
        m = sim.masses
        P.append(m @ sim.v)
        L.append(np.sum(m * (sim.x[:, 0] * sim.v[:, 1] - sim.x[:, 1] * sim.v[:, 0])))
    return sim, np.array(energies), np.array(P), np.array(L)


def test_symplectic_energy_error_shrinks_with_the_step():
    errors = []
    for substeps in (40, 80, 160):
        _, E, _, _ = _free_vibration("symplectic_euler", 0.01, substeps, 0.5)
        errors.append(np.abs(E - E[0]).max() / E[0])
    assert errors[0] < 0.05
    # first order: halving the step about halves the energy error
    assert 1.6 < errors[0] / errors[1] < 2.5
    assert 1.6 < errors[1] / errors[2] < 2.5


def test_symplectic_conserves_momentum_to_round_off():
    sim = bent_simulator(10, medium="none", method="symplectic_euler")
    m = sim.masses
    P0 = m @ sim.v
    L0 = np.sum(m * (sim.x[:, 0] * sim.v[:, 1] - sim.x[:, 1] * sim.v[:, 0]))
    for _ in range(100):
        assert sim.step()
    P1 = m @ sim.v
    L1 = np.sum(m * (sim.x[:, 0] * sim.v[:, 1] - sim.x[:, 1] * sim.v[:, 0]))
    assert np.abs(P1 - P0).max() < 1e-11
    assert abs(L1 - L0) < 1e-11
    assert sim.elastic_energy() > 1e-3  # the body really was deforming


def test_backward_euler_loses_energy_monotonically():
    _, E, P, _ = _free_vibration("backward_euler", 0.01, None, 2.0)
    assert np.all(np.diff(E) <= 1e-12 * E[0])
    assert E[-1] < 0.9 * E[0]
    assert np.abs(P).max() < 1e-9  # and keeps momentum zero


def test_backward_euler_converges_at_first_order():
    T = 0.2
    ref, *_ = _free_vibration("symplectic_euler", 1e-4, 4, T)
    errs = []
    for h in (0.004, 0.002, 0.001):
        sim, *_ = _free_vibration("backward_euler", h, None, T)
        errs.append(np.abs(sim.x - ref.x).max())
    assert 1.6 < errs[0] / errs[1] < 2.4
    assert 1.6 < errs[1] / errs[2] < 2.4


@pytest.mark.parametrize(
    ("method", "steps", "first_ratio"),
    [("sdirk2", (0.008, 0.004, 0.002), 3.2), ("bdf2", (0.004, 0.002, 0.001), 2.5)],
)
def test_second_order_methods_quarter_the_error_when_the_step_halves(method, steps, first_ratio):
    """Against SDIRK2 itself at h = 1 ms / 64, after 0.2 s of free vibration.

    Measured at h = 8, 4, 2, 1 ms: SDIRK2 1.0e-3, 2.5e-4, 5.7e-5, 1.35e-5 m (ratios 4.2);
    BDF2 2.7e-3, 1.65e-3, 5.2e-4, 1.25e-4 m (ratios 1.6, 3.2, 4.1: second order once the step
    resolves the rod, below about 4 ms); backward Euler 1.6e-2, 8.9e-3, 4.7e-3 at 8, 4, 2 ms.
    The Newton tolerance is tightened to 1e-10 m/s: at 1e-6 the converged residuals leave about
    1e-4 m after 0.2 s, which the finer steps would reach.
    """
    T = 0.2
    ref, *_ = _free_vibration("sdirk2", 0.001, 64, T, newton_tol=1e-10)
    errs = []
    for h in steps:
        sim, *_ = _free_vibration(method, h, None, T, newton_tol=1e-10)
        errs.append(np.abs(sim.x - ref.x).max())
    assert first_ratio < errs[0] / errs[1] < 4.8
    assert 3.2 < errs[1] / errs[2] < 4.8
    be, *_ = _free_vibration("backward_euler", steps[0], None, T)
    assert errs[0] < np.abs(be.x - ref.x).max() / 5


def test_bdf2_starts_each_fresh_state_with_an_sdirk2_step_then_uses_its_history():
    sims = {
        m: Simulator(SimConfig(rod=Rod(damping_bend=0.5), integrator=Integrator(method=m)))
        for m in ("bdf2", "sdirk2")
    }
    u = np.linspace(-1.0, 1.0, sims["bdf2"].N - 2)

    def step(m):
        assert sims[m].step(u_k=u)
        return sims[m].x.copy(), sims[m].v.copy()

    for _ in range(2):  # from the reset state, then from a state set by hand
        first = [step(m) for m in ("bdf2", "sdirk2")]
        assert all(np.array_equal(a, b) for a, b in zip(*first, strict=True))
        second = [step(m) for m in ("bdf2", "sdirk2")]
        # the two-step formula: another second-order step (measured 4.6 % of the largest
        # velocity apart, two steps into the start from rest)
        assert not np.array_equal(second[0][1], second[1][1])
        assert np.abs(second[0][1] - second[1][1]).max() < 0.1 * np.abs(second[1][1]).max()
        for sim in sims.values():
            sim.set_state(x=sims["sdirk2"].x, v=sims["sdirk2"].v)


def test_uniform_rest_curvature_relaxes_to_a_circular_arc():
    kbar0 = 0.3
    # water + damping to settle; Newton's tolerance set far below the velocity asserted (at the
    # default, 1e-6 m/s, the settled velocity wanders between 0.5 and 3e-6 m/s from step to step)
    sim = Simulator(
        SimConfig(
            rod=Rod(N=12, damping_bend=2.0, damping_stretch=2.0),
            integrator=Integrator(newton_tol=1e-9),
        )
    )
    sim.reset(kbar=np.full(10, kbar0))  # a straight body with curved rest shape
    sim.reset(x=body_from_curvature(np.zeros(10), sim.lbar), kbar=np.full(10, kbar0))
    for _ in range(1500):  # 15 s: the damping settles it, not the integrator (sdirk2)
        assert sim.step()
    assert np.abs(sim.v).max() < 1e-7  # measured 1.4e-9 to 4.1e-9 from 7.5 s on
    np.testing.assert_allclose(sim.kappa, kbar0, atol=1e-9)  # measured 2e-11
    # nodes on a circle of radius l / (2 sin(phi/2)), phi = 2 atan(kbar/2)
    x = sim.x
    phi = 2 * np.arctan(kbar0 / 2)
    R = 0.18 / (2 * np.sin(phi / 2))
    A = np.column_stack([2 * x, np.ones(len(x))])
    cx, cy, c = np.linalg.lstsq(A, (x**2).sum(1), rcond=None)[0]
    radii = np.hypot(x[:, 0] - cx, x[:, 1] - cy)
    np.testing.assert_allclose(radii, R, rtol=1e-6)


def _bending_frequencies(N: int, L: float = 1.62, M: float = 7.2) -> np.ndarray:
    rod = Rod(N=N, edge_length=L / (N - 1), edge_mass=M / (N - 1))
    sim = Simulator(SimConfig(rod=rod, medium="none"))
    _, dFdx, _ = sim.force_jacobians()
    s = 1 / np.sqrt(np.repeat(sim.masses, 2))
    w2 = np.sort(np.linalg.eigvalsh(-dFdx * s[:, None] * s[None, :]))
    assert np.abs(w2[:3]).max() < 1e-6 * w2[3]  # two translations and a rotation
    return np.sqrt(w2[3:5])


def test_free_free_bending_frequencies_approach_euler_bernoulli():
    L, M = 1.62, 7.2
    EI = Rod().EI
    exact = np.array([4.7300407, 7.8532046]) ** 2 * np.sqrt(EI / (M / L * L**4))
    errors = [np.abs(_bending_frequencies(N, L, M) / exact - 1) for N in (10, 20, 50)]
    assert np.all(errors[0] > errors[1]) and np.all(errors[1] > errors[2])
    assert np.all(errors[2] < 0.02)


def test_simulated_vibration_has_the_first_mode_frequency():
    N, L, M = 20, 1.62, 7.2
    w1 = _bending_frequencies(N, L, M)[0]
    rod = Rod(N=N, edge_length=L / (N - 1), edge_mass=M / (N - 1))
    sim = Simulator(
        SimConfig(rod=rod, medium="none", integrator=Integrator(method="symplectic_euler", h=1e-3))
    )
    # first mode shape from the eigenvector, small amplitude
    _, dFdx, _ = sim.force_jacobians()
    s = 1 / np.sqrt(np.repeat(sim.masses, 2))
    vals, vecs = np.linalg.eigh(-dFdx * s[:, None] * s[None, :])
    mode = (vecs[:, 3] * s).reshape(N, 2)
    sim.reset(x=sim.x + 1e-3 * mode / np.abs(mode).max())
    y = []
    for _ in range(3000):
        sim.step()
        y.append(sim.x[0, 1])
    y = np.array(y) - np.mean(y)
    crossings = np.flatnonzero(np.diff(np.sign(y)) != 0)
    period = 2 * np.mean(np.diff(crossings)) * 1e-3
    assert abs(2 * np.pi / period / w1 - 1) < 0.01


def _swim(fluid: Fluid, T: float = 8.0) -> tuple[np.ndarray, float]:
    sim = Simulator(SimConfig(fluid=fluid))
    N, h = sim.N, sim.h
    alpha, omega, delta = np.pi / 6, 2 * np.pi / 3, np.pi / 4
    k0, _ = serpenoid(serpenoid_phase(0.0, N - 2, omega, delta), omega, alpha)
    sim.reset(x=body_from_curvature(k0, sim.lbar), kbar=k0)
    c0 = sim.com
    for n in range(round(T / h)):
        _, kdot = serpenoid(serpenoid_phase((n + 0.5) * h, N - 2, omega, delta), omega, alpha)
        assert sim.step(u_k=kdot), sim.failure
    return sim.com - c0, sim.fluid_energy


def test_serpenoid_swims_toward_the_head_and_not_with_isotropic_drag():
    d, e_fluid = _swim(Fluid())
    assert d[0] > 0.5  # metres in 8 s, toward +x where the head points
    assert e_fluid > 0
    rod = Rod()
    # c_t = c_n: C_f = 4 C_D a / (pi (a + b)); no added mass
    iso = Fluid(C_f=4 * 1.75 * rod.a / (np.pi * (rod.a + rod.b)), C_D=1.75, C_A=0.0)
    d_iso, _ = _swim(iso)
    assert np.linalg.norm(d_iso) < 0.1 * np.linalg.norm(d)


def test_steps_are_bitwise_deterministic():
    runs = []
    for _ in range(2):
        sim = bent_simulator(10, medium="water")
        u = np.linspace(-1, 1, 8)
        for _ in range(50):
            sim.step(u_k=u)
        runs.append((sim.x, sim.v, sim.fluid_energy))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] == runs[1][2]


@pytest.mark.parametrize("N", [3, 10, 40])
def test_the_shared_edge_geometry_gives_turning_and_edge_frames_bit_for_bit(N):
    # the force kernels read every edge's length and tangent from one pass (edge_geometry); the
    # results of the whole simulator stay those of computing them at every use only if each
    # quantity is bitwise what turning and edge_frame give from the positions
    sim = bent_simulator(N, medium="water")
    q, v = sim.arrays.q, sim.arrays.v
    geo = np.full((2, q.size), np.nan)
    geometry.edge_geometry(q, geo)
    for j in range(1, N - 1):
        assert _turning_at(geo, j) == _turning(q, j)
    for i in range(N - 1):
        assert _edge_frame_at(geo, v, i) == _edge_frame(q, v, i)


@pytest.mark.parametrize(
    "medium, method, substeps",
    [
        ("water", "sdirk2", 1),
        ("water", "bdf2", 2),
        ("water", "backward_euler", 1),
        ("ground", "backward_euler", 2),
        ("water", "symplectic_euler", 20),
    ],
)
def test_every_step_leaves_the_edge_geometry_of_its_positions(medium, method, substeps):
    # the observation reads the edges from buf[B_GEO] without making them again: every step must
    # end with them made at its final positions, whichever sub-step made them last
    # (and a reset's observation, without a step: set_state leaves them too)
    sim = bent_simulator(10, medium=medium, method=method, substeps=substeps)  # ends in set_state
    geo = np.empty((2, sim.arrays.q.size))
    u_k, u_l = np.linspace(-1, 1, 8), np.linspace(-0.2, 0.2, 9)
    for step in range(7):
        if step > 0:
            assert sim.step(u_k=u_k, u_l=u_l), sim.failure
        geometry.edge_geometry(sim.arrays.q, geo)
        assert np.array_equal(sim.arrays.buf[layout.B_GEO : layout.B_GEO + 2, :-2], geo[:, :-2])


@pytest.mark.parametrize(
    "medium, method, k", [("ground", "backward_euler", 3), ("water", "symplectic_euler", 20)]
)
def test_a_step_of_k_sub_steps_is_k_steps_of_a_kth_of_its_length(medium, method, k):
    # a sub-step's start reads the edges that the sub-step before it left in buf[B_GEO], as a
    # step reads the last step's: the state is the same bits either way, and the actuator's work
    # (each start's power in the trapezoidal rule) is the same sum up to its order
    whole = bent_simulator(10, medium=medium, method=method, h=0.01, substeps=k)
    parts = bent_simulator(10, medium=medium, method=method, h=0.01 / k, substeps=1)
    u_k, u_l = np.linspace(-1, 1, 8), np.linspace(-0.2, 0.2, 9)
    for _ in range(4):
        assert whole.step(u_k=u_k, u_l=u_l), whole.failure
        for _ in range(k):
            assert parts.step(u_k=u_k, u_l=u_l), parts.failure
        for name in ("q", "v", "kbar", "lbar"):
            assert np.array_equal(getattr(whole.arrays, name), getattr(parts.arrays, name)), name
        work = whole.energy_ledger()["actuator_work"]
        assert work != 0.0
        assert work == pytest.approx(parts.energy_ledger()["actuator_work"], rel=1e-12, abs=0.0)


@njit
def _turning(q, j):
    return geometry.turning(q, j)


@njit
def _turning_at(geo, j):
    return geometry.turning_at(geo, j)


@njit
def _edge_frame(q, v, i):
    return geometry.edge_frame(q, v, i)


@njit
def _edge_frame_at(geo, v, i):
    return geometry.edge_frame_at(geo, v, i)


@pytest.mark.parametrize("N", [3, 200])
def test_extreme_resolutions_step(N):
    sim = Simulator(SimConfig(rod=Rod(N=N, edge_length=1.62 / (N - 1))))
    for _ in range(20):
        assert sim.step(u_k=np.full(N - 2, 0.5)), sim.failure
    # a uniform rest curvature loads only the free ends at first; on average the body follows
    assert sim.kappa.mean() > 0.2 * sim.kbar.mean()


def test_explicit_substeps_keep_material_damping_stable():
    """Explicit Kelvin-Voigt damping is stable only while the sub-step is shorter than the damping time.

    That is the fastest damping time: on short, light edges that limit, not the elastic one, sets the
    sub-steps (docs/model.md §5a).
    """
    rod = Rod(N=30, edge_length=1.62 / 29, edge_mass=7.2 / 29, damping_bend=1.0, damping_stretch=5.0)
    elastic_only = Simulator(
        SimConfig(
            rod=dataclasses.replace(rod, damping_bend=0.0, damping_stretch=0.0),
            integrator=Integrator(method="symplectic_euler"),
        )
    )
    sim = Simulator(SimConfig(rod=rod, integrator=Integrator(method="symplectic_euler")))
    assert sim.substeps > 2 * elastic_only.substeps
    sim.reset(x=body_from_curvature(0.3 * np.sin(np.arange(1, 29) / 3.0), sim.lbar))
    for _ in range(20):
        assert sim.step(), sim.failure
    assert np.abs(sim.v).max() < 1.0
