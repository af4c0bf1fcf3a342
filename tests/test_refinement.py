"""Refining one robot in space.

The same eel (length, mass, cross-section, material, gait) with more nodes converges to one
continuous body.

``Rod.N`` alone adds edges of the same length; ``Rod.refined`` (or the key ``refine``) keeps
the robot and shrinks the edges, scales the material damping like the stiffnesses, and the
gaits are mapped onto arc length (``gaits.serpenoid_on_nodes``).
"""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym import Rod, SimConfig, Simulator, body_from_curvature
from soft_snake_gym.config import ConfigError, from_dict, load_sim_config
from soft_snake_gym.gaits import serpenoid_on_nodes
from soft_snake_gym.policies import CurvaturePID, InchingWave, OpenLoopSerpenoid


def test_refined_rod_is_the_same_robot_with_shorter_edges():
    rod = Rod(damping_bend=2.0, damping_stretch=3.0)
    fine = rod.refined(40)
    assert (fine.N, fine.refined_from, fine.design_nodes) == (40, 10, 10)
    assert fine.length == pytest.approx(rod.length) and fine.total_mass == pytest.approx(rod.total_mass)
    assert (fine.a, fine.b, fine.EA, fine.EI) == (rod.a, rod.b, rod.EA, rod.EI)
    assert fine.edge_ratio == pytest.approx(fine.edge_length / rod.edge_length)
    # damping per node scales like EI/l and EA/l: the same dissipation per unit length
    assert fine.damping_bend * fine.edge_length == pytest.approx(rod.damping_bend * rod.edge_length)
    assert fine.damping_stretch * fine.edge_length == pytest.approx(rod.damping_stretch * rod.edge_length)
    # refinements compose and undo; the design robot is kept
    twice = rod.refined(20).refined(40)
    assert twice.refined_from == 10
    for f in ("edge_length", "edge_mass", "damping_bend", "damping_stretch"):
        assert getattr(twice, f) == pytest.approx(getattr(fine, f))
    assert Rod().refined(10) == Rod() and fine.refined(10).refined_from is None
    assert fine.refined(10).edge_length == pytest.approx(0.18)
    # plain N still adds edges of the same length: a longer robot
    assert Rod(N=40).length == pytest.approx(39 * 0.18)


def test_refine_from_yaml_and_env_keywords(tmp_path):
    path = tmp_path / "fine.yaml"
    path.write_text("rod: {refine: 40, E_bend: 1.87e4}\n")
    config = load_sim_config(path)
    assert config.rod == Rod(E_bend=1.87e4).refined(40)
    env = gym.make("SoftEel-v0", rod={"refine": 40}).unwrapped
    assert env.N == 40 and env.total_mass == pytest.approx(7.2)
    assert env.sim.config.rod.length == pytest.approx(1.62)
    # per-node action bounds follow the edge: the same bending rate per metre at action 1
    ratio = 9 / 39
    assert env.max_curvature_rate == pytest.approx(2 * math.pi * ratio)
    assert env.max_rest_curvature == pytest.approx(4.0 * ratio)
    assert env.observation_space.high[:38] == pytest.approx(np.full(38, 8.0 * ratio))
    worm = gym.make("SoftWorm-v0", rod={"refine": 19}).unwrapped
    assert worm.max_length_rate == pytest.approx(0.3 * 9 / 18)
    # a dumped refined rod loads back to itself
    assert from_dict(Rod, dataclasses.asdict(config.rod)) == config.rod


@pytest.mark.parametrize("value", [2, 40.0, "40", True, 10**6])
def test_bad_refine_is_rejected_naming_the_field(value):
    with pytest.raises(ConfigError, match=r"Rod\.refine = .* must be an integer in \[3, 100000\]"):
        from_dict(Rod, {"refine": value})
    with pytest.raises(ValueError, match=r"Rod\.refine"):
        gym.make("SoftEel-v0", rod={"refine": value})


def test_bad_refined_from_is_rejected():
    with pytest.raises(ValueError, match=r"Rod\.refined_from = 2 must be an integer"):
        Rod(refined_from=2)


def test_gait_mapping_is_the_identity_on_the_design_robot_and_scales_with_the_edge():
    assert serpenoid_on_nodes(math.pi / 6, None, 10) == (math.pi / 6, 2 * math.pi / 8, 0.0)
    assert serpenoid_on_nodes(0.3, 0.5, 12, 12, 0.1) == (0.3, 0.5, 0.1)
    alpha, delta, gamma = serpenoid_on_nodes(math.pi / 6, None, 40, 10, 0.2)
    l_d, l = 1.62 / 9, 1.62 / 39
    # same wave on arc length: amplitude per metre and wavelength in metres
    assert alpha / l == pytest.approx((math.pi / 6) / l_d) and gamma / l == pytest.approx(0.2 / l_d)
    assert 2 * math.pi * l / delta == pytest.approx(8 * l_d)


# the pulse's peak rate exceeds max_length_rate here: its clipping warning is expected
@pytest.mark.filterwarnings("ignore:inching. the pulse wave's peak rate")
def test_controllers_command_the_same_wave_on_arc_length():
    """At equal arc length and time, the refined robot's controllers ask for the design's targets.

    At equal arc length s and time t, they ask for the same turning angle per metre (serpenoid) and
    the same strain (length wave) as the design's.
    """
    t = np.array([0.37, 1.9])
    phi = {}
    for N in (10, 19):
        env = gym.make("SoftEel-v0", rod={"refine": N})
        pid = CurvaturePID(env, alpha=0.5, delta=0.7, gamma=0.05)
        kappa_des, _ = pid.desired(pid.clock_phase(t))
        phi[N] = 2 * np.arctan(kappa_des / 2) / env.unwrapped.sim.config.rod.edge_length
    np.testing.assert_allclose(phi[19][:, 1::2], phi[10], rtol=1e-12)  # node 2k of 19 is node k of 10
    strain = {}
    for N in (10, 19):
        env = gym.make("SoftWorm-v0", rod={"refine": N})
        wave = InchingWave(env, delta_l=0.9, l0=0.2)
        strain[N] = wave.desired(t)[0] / env.unwrapped.sim.config.rod.edge_length
    np.testing.assert_allclose(
        strain[19][:, ::2], strain[10], rtol=1e-12
    )  # edge 2k of 19 starts at edge k of 10


def test_refined_serpenoid_start_is_the_same_body():
    """The env's serpenoid start, at N = 10, 19, 37 (edges 1, 1/2, 1/4 of the design's).

    Node positions at the design nodes' arc lengths converge to one curve.
    """
    shapes = {}
    for N in (10, 19, 37):
        env = gym.make("SoftEel-v0", rod={"refine": N}, initial_shape="serpenoid", reset_noise_scale=0.0)
        env.reset(seed=0)
        x = env.unwrapped.sim.x
        shapes[N] = x[:: (N - 1) // 9]  # the 10 nodes at arc lengths 0, 0.18, ..., 1.62 m
    d1 = np.abs(shapes[19] - shapes[10]).max()
    d2 = np.abs(shapes[37] - shapes[19]).max()
    assert d1 < 0.05 and d2 < d1 / 2, (d1, d2)


@pytest.mark.parametrize("kind", ["bend", "stretch"])
def test_refined_damping_relaxes_at_the_continuum_rate(kind):
    """Kelvin-Voigt relaxation of a free rod (no medium, strong damping).

    A bend decays at ``EI / (l damping_bend)`` and a stretch at ``EA / (l damping_stretch)``, rates
    that the refinement keeps whatever N (unscaled damping would make them grow like 1/l).
    """
    design = Rod(damping_bend=56.0) if kind == "bend" else Rod(damping_stretch=45_000.0)
    rate = design.EI / design.damping_bend if kind == "bend" else design.EA / design.damping_stretch
    rate /= design.edge_length
    for N in (10, 20, 40):
        rod = design.refined(N)
        sim = Simulator(SimConfig(rod=rod, medium="none"))
        n, l = N - 2, rod.edge_length
        if kind == "bend":  # a uniform arc of 0.4 rad per body length, rest shape straight
            arc = np.full(n, 2 * math.tan(0.2 * l / 1.62))
            sim.reset(x=body_from_curvature(arc, np.full(N - 1, l)), kbar=np.zeros(n))
        else:  # stretched by 1 %
            x = np.zeros((N, 2))
            x[:, 0] = np.arange(N) * l * 1.01
            sim.reset(x=x)
        sizes = []
        for steps in (20, 30):
            sim.advance(steps)
            bend = np.sum(2 * np.arctan(sim.kappa / 2))  # total turning angle [rad]
            sizes.append(bend if kind == "bend" else sim.edge_lengths.sum() - rod.length)
        measured = math.log(sizes[0] / sizes[1]) / 0.3
        assert measured == pytest.approx(rate, rel=0.03), (N, measured, rate)


def _episode(N: int, policy, seconds: float = 6.0, window: float = 3.0) -> tuple[float, float]:
    """Speed [m/s] and mean fluid power [W] over the last ``window`` s of an episode.

    ``window`` is one gait period; the episode is of the thesis robot refined to N nodes, started at
    rest on the gait's shape.
    """
    env = gym.make(
        "SoftEel-v0",
        rod={"refine": N},
        initial_shape="serpenoid",
        serpenoid_alpha=math.pi / 6,
        reset_noise_scale=0.0,
    )
    controller = policy(env)
    obs, _ = env.reset(seed=0)
    steps, last = round(seconds / 0.01), round(window / 0.01)
    state, com, power = None, [], []
    for i in range(steps):
        action, state = controller.predict(obs, state, np.array([i == 0]))
        obs, _, terminated, _, info = env.step(action)
        assert not terminated, info["failure"]
        com.append((info["x_position"], info["y_position"]))
        power.append(info["fluid_power"])
    com = np.array(com)
    return float(np.linalg.norm(com[-1] - com[-1 - last]) / window), float(np.mean(power[-last:]))


@pytest.mark.parametrize("policy", [OpenLoopSerpenoid, CurvaturePID], ids=["open-loop", "pid"])
def test_speed_and_fluid_power_converge_as_the_robot_is_refined(policy):
    """The thesis gait (alpha = pi/6, omega = 2 pi/3, one wave) on the same robot at N = 10, 20, 40.

    The changes in speed and fluid power shrink at least by half each time the edges halve
    (measured: about 4x, second order).
    """
    results = {N: _episode(N, policy) for N in (10, 20, 40)}
    print(f"\n{policy.name}: " + ", ".join(f"N={N}: {s:.4f} m/s {p:.3f} W" for N, (s, p) in results.items()))
    for k, name in enumerate(("speed", "fluid power")):
        m10, m20, m40 = (results[N][k] for N in (10, 20, 40))
        coarse, fine = abs(m20 - m10), abs(m40 - m20)
        assert coarse > 2 * fine, f"{policy.name} {name}: N=10, 20, 40 give {m10}, {m20}, {m40}"
        assert fine < 0.03 * abs(m40), f"{policy.name} {name}: N=20 and 40 differ by {fine}"
