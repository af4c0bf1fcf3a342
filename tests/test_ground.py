"""Stick-slip friction on the ground (docs/model.md §5) and the inching length wave (§6)."""

from __future__ import annotations

import numpy as np
import pytest

from soft_snake_gym import Ground, Integrator, SimConfig, Simulator, body_from_curvature
from soft_snake_gym.gaits import length_wave, pulse_wave
from soft_snake_gym.physics import layout as L
from soft_snake_gym.physics import stepper
from soft_snake_gym.physics.forces import kinetic_friction

G = Ground()


def pushed(frac: float, method: str = "backward_euler") -> Simulator:
    """A straight rod at rest on the ground pushed along +x by frac * mu_s * m_i * g per node."""
    sim = Simulator(SimConfig(medium="ground", integrator=Integrator(method=method)))
    force = np.zeros((sim.N, 2))
    force[:, 0] = frac * G.mu_s * sim.masses * G.g
    sim.set_external_force(force)
    return sim


@pytest.mark.parametrize("method", ["backward_euler", "symplectic_euler"])
def test_push_below_static_friction_stays_stuck(method):
    sim = pushed(0.95, method)
    x0 = sim.x
    for _ in range(100):
        assert sim.step()
    assert np.array_equal(sim.x, x0)
    assert sim.stuck.all()
    assert sim.friction_work == 0.0


@pytest.mark.parametrize("method", ["backward_euler", "symplectic_euler"])
def test_push_above_static_friction_breaks_away_then_decelerates_at_mu_d_g(method):
    sim = pushed(1.1, method)
    for _ in range(50):
        assert sim.step()
    assert not sim.stuck.any()
    # accelerates at (1.1 mu_s - mu_d) g while pushed
    expected = (1.1 * G.mu_s - G.mu_d) * G.g * 0.5
    assert sim.com_velocity[0] == pytest.approx(expected, rel=1e-3)
    sim.set_external_force(None)
    v0 = sim.com_velocity[0]
    for _ in range(10):
        assert sim.step()
    decel = (v0 - sim.com_velocity[0]) / 0.1
    assert decel == pytest.approx(G.mu_d * G.g, rel=1e-3)
    # kinetic energy goes into friction work, then the rod stops and sticks again
    for _ in range(100):
        assert sim.step()
    assert np.abs(sim.v).max() == 0.0 and sim.stuck.all()
    assert sim.friction_work > 0


@pytest.mark.parametrize("method", ["backward_euler", "symplectic_euler"])
def test_a_node_braked_through_rest_stays_at_rest_below_static_friction(method):
    """docs/model.md §5: kinetic friction brakes a node and never pushes it back.

    A rod sliding forward at 5 mm/s, pushed back by 0.95 mu_s m g (above mu_d m g): push and
    friction stop it within a tenth of a 10 ms step. The implicit step also has a solution in
    which the rod ends the step sliding backward at 2.4 cm/s (friction then pointing forward),
    after which a push below static friction would drive it back for ever; the law holds it
    at rest, since it passed through rest.
    """
    sim = pushed(-0.95, method)
    sim.set_state(v=np.tile([0.005, 0.0], (sim.N, 1)))
    x0 = sim.x
    for _ in range(50):
        assert sim.step()
    assert sim.stuck.all() and np.abs(sim.v).max() == 0.0
    assert np.abs(sim.x - x0).max() < 1e-4


def inch(
    direction: int,
    cycles: int = 4,
    eps: float = 0.2,
    omega: float = np.pi,
    delta_l: float = 2 * np.pi / 9,
    duty: float | None = None,
    ground: Ground = G,
) -> tuple[float, Simulator]:
    """Metres per cycle of a length wave run open loop (``duty``: the peristaltic pulse)."""
    sim = Simulator(SimConfig(medium="ground", ground=ground))
    N, l0, h = sim.N, 0.18, sim.h

    def wave(t):
        if duty is None:
            return length_wave(t, N - 1, l0, eps, omega, delta_l, direction)
        return pulse_wave(t, N - 1, l0, eps, omega, delta_l, duty, direction)

    lbar0, _ = wave(0.0)
    sim.reset(x=body_from_curvature(np.zeros(N - 2), lbar0), lbar=lbar0)
    c0 = sim.com
    for n in range(round(cycles * 2 * np.pi / omega / h)):
        _, ldot = wave((n + 0.5) * h)
        assert sim.step(u_l=ldot), sim.failure
    return (sim.com - c0)[0] / cycles, sim


def test_peristaltic_pulse_moves_the_worm_with_the_wave_and_the_sine_wave_barely():
    """docs/model.md §6: with isotropic friction a worm moves by anchoring.

    The pulse changes a few edges at a time and anchors the rest, so it carries the worm with the
    wave; the sinusoidal wave changes every edge at once and anchors little.
    """
    forward, sim = inch(+1, duty=0.5)
    backward, _ = inch(-1, duty=0.5)
    sine, _ = inch(+1)
    # a pulse from tail to head moves the worm toward its head (+x), the reverse pulse back;
    # each cycle carries it a good part of the compression the pulse holds, 0.5 * eps * l0 * 4.5
    assert forward > 0.015 and backward < -0.015
    assert abs(sine) < 0.1 * forward
    assert abs(sim.com[1]) < 1e-9  # a straight worm stays on its line
    assert sim.friction_work > 0 and sim.actuator_energy > 0


def violent_lengths(sim: Simulator, rng: np.random.Generator) -> np.ndarray:
    """Length rates of +-0.15 to 0.3 m/s per edge, at random, kept within the rest-length limits."""
    lo, hi = 0.5 * 0.18, 1.5 * 0.18
    u_l = rng.choice([-0.3, 0.3], size=sim.N - 1) * rng.uniform(0.5, 1.0, size=sim.N - 1)
    return np.clip(u_l, (lo - sim.lbar) / sim.h, (hi - sim.lbar) / sim.h)


def test_friction_never_gives_more_than_static_friction_impulse():
    """Internal forces cancel, so the body's momentum changes only by friction.

    Per step at most mu_s * M * g * dt, however violently the worm actuates. A node held stuck
    through a whole step against larger forces would break this.
    """
    sim = Simulator(SimConfig(medium="ground"))
    rng = np.random.default_rng(11)
    M, h = sim.masses.sum(), sim.h
    bound = G.mu_s * M * G.g * h
    worst = 0.0
    for _ in range(400):
        p0 = sim.masses @ sim.v
        assert sim.step(u_l=violent_lengths(sim, rng)), sim.failure
        worst = max(worst, np.linalg.norm(sim.masses @ sim.v - p0) / bound)
    assert worst <= 1.0 + 1e-6
    assert worst > 0.2  # the test really loads the friction


def test_friction_obeys_coulomb_at_the_end_of_every_step():
    """docs/model.md §5 at the end of the step, node by node, under violent actuation.

    The friction force ``f = m (v - v0)/h - F(q1, v1)`` holds a node at rest within ``mu_s F_N`` and
    is ``mu_d F_N`` against the end velocity of a sliding node (to the smoothing far below V_tol).
    """
    sim = Simulator(SimConfig(medium="ground"))
    rng = np.random.default_rng(5)
    h, m = sim.h, sim.masses
    fn = m * G.g
    n_stuck = n_sliding = 0
    for _ in range(300):
        v0 = sim.v
        assert sim.step(u_l=violent_lengths(sim, rng)), sim.failure
        f = m[:, None] * (sim.v - v0) / h - sim.elastic_forces()
        size = np.linalg.norm(f, axis=1)
        speed = np.linalg.norm(sim.v, axis=1)
        stuck = sim.stuck
        assert np.all(speed[stuck] < 1e-15)
        assert np.all(size[stuck] <= G.mu_s * fn[stuck] * (1 + 1e-6) + 1e-9)
        sliding = ~stuck
        assert np.all(speed[sliding] >= G.V_tol)
        np.testing.assert_allclose(size[sliding], G.mu_d * fn[sliding], rtol=1e-2)
        along = np.einsum("ij,ij->i", f[sliding], sim.v[sliding]) / (size[sliding] * speed[sliding])
        np.testing.assert_allclose(along, -1.0, atol=1e-6)
        n_stuck += stuck.sum()
        n_sliding += sliding.sum()
    assert n_stuck > 100 and n_sliding > 100  # both branches of the law were exercised


def test_contact_passes_converge_in_few_newton_steps_under_violent_actuation():
    """docs/model.md §5, step 2: a node turned against the way it slides is held at once.

    That includes a node released in the step, tested against the push it was released along:
    untested, it swung about rest, friction flipping at each iterate, until a line search brought
    it below ``V_tol`` (these 300 steps took 8.0 residuals a step on average and up to 29; now 5.5
    and 12).
    """
    sim = Simulator(SimConfig(medium="ground"))
    rng = np.random.default_rng(5)
    work = []
    for _ in range(300):
        assert sim.step(u_l=violent_lengths(sim, rng)), sim.failure
        w = sim.newton_work
        work.append(w["jacobians"] + w["residuals"])
    assert np.mean(work) < 6.5 and max(work) <= 16


def test_a_node_turned_against_its_release_is_held_and_the_rest_take_the_update():
    """The reversal test's reference for a released node is its release guess, not its start velocity."""
    n = 6
    v = np.array([0.002, 0.0, 0.01, 0.0, 0.0, 0.0])  # node 0 released along +x, node 1 sliding, node 2 held
    vslide = v.copy()
    ibuf = np.zeros((L.N_IBUF, n), dtype=np.int64)
    ibuf[L.I_FRICTION, :3] = [L.SLIDING, L.SLIDING, L.STUCK]
    ibuf[L.I_SWITCHES, :3] = [1, 0, 1]  # node 0 was released in this step
    dv = np.array([-0.005, 0.001, -0.002, 0.0, -0.0, -0.0])  # turns node 0 back; node 1 goes on
    assert stepper._reversal_in_update(v, dv, vslide, ibuf, n)
    assert ibuf[L.I_FRICTION, :3].tolist() == [L.STUCK, L.SLIDING, L.STUCK]
    assert ibuf[L.I_SWITCHES, :3].tolist() == [2, 0, 1]
    np.testing.assert_array_equal(v, [0.0, 0.0, 0.008, 0.0, 0.0, 0.0])
    # a node at its last change slides on: the passes end
    ibuf[L.I_FRICTION, 0], ibuf[L.I_SWITCHES, 0], v[0] = L.SLIDING, L.MAX_SWITCHES, 0.002
    assert not stepper._stick_reversing_nodes(v, dv, 1.0, vslide, ibuf, n)


@pytest.mark.parametrize("method", ["backward_euler", "symplectic_euler"])
@pytest.mark.parametrize(
    "direction,coef", [((1.0, 0.0), "mu_forward"), ((-1.0, 0.0), "mu_backward"), ((0.0, 1.0), "mu_lateral")]
)
def test_anisotropic_kinetic_friction_depends_on_the_sliding_direction(method, direction, coef):
    ground = Ground(mu_forward=0.3, mu_backward=1.0, mu_lateral=0.6)
    sim = Simulator(SimConfig(medium="ground", ground=ground, integrator=Integrator(method=method)))
    sim.set_external_force(1.1 * G.mu_s * G.g * sim.masses[:, None] * np.array(direction))
    for _ in range(50):
        assert sim.step()
    assert not sim.stuck.any()
    # the straight rod (head along +x) accelerates at (1.1 mu_s - mu_direction) g
    expected = (1.1 * G.mu_s - getattr(ground, coef)) * G.g * 0.5
    assert float(sim.com_velocity @ np.array(direction)) == pytest.approx(expected, rel=2e-3)


def test_backward_friction_lets_a_symmetric_wave_move_the_worm_forward():
    """Setae-like anisotropy turns a wave that barely moves an isotropic worm into forward motion.

    Setae-like: sliding toward the tail costs more than toward the head. The isotropic worm moves
    almost nowhere; the anisotropic one moves forward whichever way the wave travels.
    """
    iso, _ = inch(-1)
    setae = Ground(mu_forward=0.3, mu_backward=1.1)
    for direction in (1, -1):
        per_cycle, _ = inch(direction, ground=setae)
        assert per_cycle > 0.01 and per_cycle > 5 * abs(iso)


@pytest.mark.parametrize("ground", [G, Ground(mu_forward=0.3, mu_backward=1.0, mu_lateral=0.6)])
def test_kinetic_friction_velocity_derivative_matches_finite_differences(ground):
    """Newton's friction rows: ``kinetic_friction``'s derivative by the node's velocity, against its force."""
    sim = Simulator(SimConfig(medium="ground", ground=ground))
    q, prm = sim.arrays.q.copy(), sim.arrays.prm
    eps2 = (0.1 * ground.V_tol) ** 2
    fn = sim.masses[1] * ground.g
    rng = np.random.default_rng(0)
    for speed in (3e-4, 0.02, 0.5):  # within friction's smoothing, and well beyond it
        v = np.zeros_like(q)
        v[2:4] = speed * rng.normal(size=2) / np.sqrt(2)
        fx, fy, *d = kinetic_friction(q, v, 1, fn, eps2, prm)
        fd = np.empty((2, 2))
        h = 1e-6 * speed
        for j in range(2):
            vp, vm = v.copy(), v.copy()
            vp[2 + j] += h
            vm[2 + j] -= h
            fd[:, j] = (
                np.array(kinetic_friction(q, vp, 1, fn, eps2, prm)[:2])
                - np.array(kinetic_friction(q, vm, 1, fn, eps2, prm)[:2])
            ) / (2 * h)
        assert np.hypot(fx, fy) > 0.1 * ground.mu_d * fn * min(1.0, speed / 1e-3)
        np.testing.assert_allclose(np.reshape(d, (2, 2)), fd, rtol=1e-5, atol=1e-7 * np.abs(fd).max())
