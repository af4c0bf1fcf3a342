"""``SoftEel-v0``: the thesis eel swimming in water by moving its rest curvatures."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from gymnasium.spaces import Box

from soft_snake_gym.envs import task as T
from soft_snake_gym.envs.base import SoftRobotEnv
from soft_snake_gym.envs.settings import BaseSettings
from soft_snake_gym.gaits import (
    SerpenoidParams,
    max_serpenoid_amplitude,
    serpenoid,
    serpenoid_on_nodes,
    serpenoid_phase,
)
from soft_snake_gym.params import check_number
from soft_snake_gym.physics import body_from_curvature
from soft_snake_gym.physics.geometry import polyline_crosses

__all__ = ["SwimEnv", "SwimSettings"]


@dataclass(frozen=True)
class SwimSettings(BaseSettings):
    """Constructor keywords of :class:`SwimEnv` (the table in its docstring)."""

    max_curvature_rate: float = 2.0 * math.pi
    max_rest_curvature: float = 4.0
    initial_shape: Literal["straight", "serpenoid"] = "straight"
    serpenoid_alpha: float = math.pi / 4
    serpenoid_delta: float | None = None
    start_on_gait: SerpenoidParams | None = None

    def __post_init__(self) -> None:
        """Check the settings of :class:`SwimEnv` on top of the shared ones."""
        super().__post_init__()
        for name in ("max_curvature_rate", "max_rest_curvature"):
            check_number(f"SwimSettings.{name}", getattr(self, name), 0.0, lo_open=True)
        check_number("SwimSettings.serpenoid_alpha", self.serpenoid_alpha, 0.0)
        if self.serpenoid_alpha >= math.pi:
            raise ValueError(f"SwimSettings.serpenoid_alpha = {self.serpenoid_alpha!r} must be in [0, pi)")
        if self.serpenoid_delta is not None:
            check_number("SwimSettings.serpenoid_delta", self.serpenoid_delta)
        if self.initial_shape not in ("straight", "serpenoid"):
            raise ValueError(
                f"SwimSettings.initial_shape = {self.initial_shape!r}; use 'straight' or 'serpenoid'"
            )
        gait = self.start_on_gait
        if gait is not None:
            if not isinstance(gait, SerpenoidParams):
                raise ValueError(
                    f"SwimSettings.start_on_gait = {gait!r} must be a mapping of serpenoid gait "
                    "parameters (alpha, omega, delta, gamma, psi0) or None"
                )
            for name in ("alpha", "omega", "gamma", "psi0") + (("delta",) if gait.delta is not None else ()):
                check_number(f"SwimSettings.start_on_gait.{name}", getattr(gait, name))
            if self.initial_shape != "straight":
                raise ValueError(
                    f"SwimSettings.start_on_gait and initial_shape = {self.initial_shape!r} both set "
                    "the start; use one (start_on_gait starts exactly on the gait, without noise)"
                )


class SwimEnv(SoftRobotEnv):
    r"""A soft eel that swims by bending: ``SoftEel-v0``.

    ## Description
    The robot of Jaya Prakash's thesis (2020) and Scott, Jaya Prakash & Paley (2021): a planar
    discrete elastic rod of N = 10 nodes (9 edges of 0.18 m and 0.8 kg, 1.62 m and 7.2 kg in
    all) in still water, with Morison-type drag and added mass (see ``docs/model.md``). The agent
    moves the rest curvature ``kbar`` of the 8 interior nodes; the body follows through its
    elasticity and the water pushes back. The task is to swim along a goal direction (+x by
    default; the body starts along +x with its head, node N-1, ahead). A serpenoid travelling
    wave from head to tail (``soft_snake_gym.gaits.serpenoid``) run open loop swims at
    0.23 m/s at alpha = pi/4, omega = pi rad/s, and at 0.13 m/s at the thesis gait (alpha =
    pi/6, omega = 2 pi/3 rad/s).

    ## Action Space
    A `Box(-1, 1, (N-2,), float32)`: the curvature rates ``u_k = max_curvature_rate * action``
    [1/s] of the interior nodes 1 … N-2, held over the control step (``d kbar/dt = u_k``).
    Actions outside [-1, 1] are clipped; a NaN or a wrong shape raises ``ValueError``. A rate
    that would carry ``kbar`` past ``±max_rest_curvature`` is cut so that ``kbar`` stops at the
    bound. The default ``max_curvature_rate = 2 pi`` 1/s covers the PID baseline's saturation
    ``1.5 alpha omega`` for every gait with ``alpha omega <= 4.19`` (e.g. alpha = pi/4 up to
    omega = 5.3 rad/s). On a refined rod (``rod={"refine": N}``, ``Rod.refined``) the
    per-node bounds ``max_curvature_rate`` and ``max_rest_curvature`` (as given, those of the
    robot as designed) are scaled by ``Rod.edge_ratio = l / l_d`` (``env.unwrapped`` holds the
    scaled values): a per-node turning angle is the curvature times the edge length, so action
    1.0 bends the body at the same rate per metre whatever N.

    ## Observation Space
    A `Box(low, high, (3(N-2)+4,), float32)`, what the robot's own sensors measure, in this order
    (``env.unwrapped.observation_structure``); values beyond the bounds are clipped:

    | Block               | Size | Bounds                        | Meaning (unit)                                          |
    |---------------------|------|-------------------------------|---------------------------------------------------------|
    | kappa               | N-2  | ±2 max_rest_curvature         | curvature ``2 tan(phi/2)`` of the interior nodes (-)    |
    | kappa_dot           | N-2  | ±4 max_curvature_rate         | exact curvature rates, docs/model.md §2 (1/s)                |
    | kbar                | N-2  | ±max_rest_curvature           | rest curvatures (-)                                     |
    | com_velocity_body   | 2    | ±max_observed_speed           | centre-of-mass velocity along the heading, lateral (m/s)|
    | goal_direction_body | 2    | ±1                            | cos, sin of (goal direction − heading)                  |

    The heading is the direction of the tail-to-head chord ``x[N-1] - x[0]``.

    ## Rewards
    ``reward = reward_forward + reward_energy + reward_ctrl + reward_failure``, each in ``info``:

    - *reward_forward* = ``forward_reward_weight * forward_speed``: the centre of mass's
      displacement along the goal direction over the step, divided by ``dt`` (m/s).
    - *reward_energy* = ``-energy_cost_weight * |P_act|``: the actuator power (docs/model.md §3,
      W), averaged in absolute value over the integrator steps of the control step.
    - *reward_ctrl* = ``-ctrl_cost_weight * ||action||^2`` (normalized action).
    - *reward_failure* = ``-failure_cost`` on the step that ends the episode by a failure.

    ## Starting State
    ``initial_shape="straight"``: a straight body with its rest shape straight, bent by
    curvatures drawn from U(-s, s) at each interior node and turned by U(-s, s) rad about +x
    (``s = reset_noise_scale``), head ahead, centre of mass at the origin, at rest. The body
    starts along +x whatever ``goal_direction``: another goal makes a steering task.
    ``initial_shape="serpenoid"``: the same around the serpenoid body ``kbar_j = 2 tan(alpha
    sin(delta j) / 2)`` (``serpenoid_alpha``, ``serpenoid_delta``; the clock phase at t = 0),
    its rest shape equal to that serpenoid (on a refined rod the same body: ``serpenoid_alpha``
    and ``serpenoid_delta`` are mapped onto arc length, ``gaits.serpenoid_on_nodes``). ``start_on_gait={"alpha": ..., "omega": ...,
    "delta": ..., "gamma": ..., "psi0": ...}`` (the fields of the baselines' serpenoid gait,
    :class:`~soft_snake_gym.gaits.SerpenoidParams`; missing ones take its defaults,
    the thesis gait): at rest on that gait, the sources' start (docs/model.md §7): curvatures and
    rest curvatures equal to ``kappa_des`` at t = 0 (``psi_j = delta j + psi0``; ``omega`` does
    not change the shape at rest), chord along +x, centre of mass at the origin, with **no**
    noise (``reset_noise_scale`` is not used). ``reset(options={"x", "v", "kbar", "lbar"})`` sets
    the initial body exactly (missing parts: at rest, straight rest shape, ``x`` built from
    ``kbar`` and ``lbar``); ``options={"goal_direction": angle}`` sets the episode's goal.
    With ``randomize``, the physics is drawn anew at each reset, the values in
    ``info["randomized"]``.

    ## Episode End
    ### Termination
    A failed physics step: a non-finite state, a self-intersecting body, runaway stretch or a
    Newton step that does not converge; ``info["failure"]`` names the reason; the observation,
    the state entries of ``info`` and ``info["metrics"]`` are those of the last valid state.
    ### Truncation
    1000 steps (10 s at the default ``dt``), by ``TimeLimit`` through ``gym.make``.

    ## Info
    Every step: ``forward_speed`` (m/s), ``x_position``, ``y_position`` (centre of mass, m),
    ``heading`` (rad), ``time`` (s), ``fluid_power``, ``actuator_power`` (signed; both averaged
    over the step, W), ``kappa``, ``kbar``, ``newton_iterations``, every ``reward_<term>``,
    ``failure`` (None or the reason) and ``metrics``, the running episode summary (docs/model.md §8):
    ``average_speed`` (distance / duration, m/s), ``distance`` (along the goal, m),
    ``displacement``, ``duration``, ``cost_of_transport`` (actuator energy / (total mass g
    distance); ``inf`` without forward progress), ``energy_fluid``, ``energy_actuator`` (sum of
    |work| per integrator step, J), ``actuator_work`` (signed, J); and ``energy``, the episode's
    energy ledger (docs/model.md §4, J, see ``Simulator.energy_ledger``): ``actuator_work`` =
    ``fluid_dissipation`` + ``damping_dissipation`` + ``friction_dissipation`` +
    ``delta_kinetic`` + ``delta_elastic`` + ``delta_fluid_kinetic`` (the water's kinetic
    energy ``T_f``) + ``error`` (what the integrator made or lost; it shrinks with the step).

    ## Arguments
    ```python
    import gymnasium as gym
    import soft_snake_gym
    env = gym.make("SoftEel-v0", max_curvature_rate=3.0, fluid={"rho": 1025.0})
    env = gym.make("SoftEel-v0", config="softeel")  # a shipped config by name, or a YAML path
    env = gym.make("SoftEel-v0", preset="thesis", start_on_gait={"alpha": math.pi / 3})
    ```
    Keywords given explicitly override those from ``config``, which override the ``preset``;
    unknown keys are rejected with the closest valid name.

    | Parameter             | Type              | Default        | Description                                                                 |
    |-----------------------|-------------------|----------------|-----------------------------------------------------------------------------|
    | `config`              | str or Path       | `None`         | YAML file of any keywords below (a `medium: water` key is accepted)         |
    | `render_mode`         | str               | `None`         | `"rgb_array"` (headless image) or `"human"` (a window; needs a display)     |
    | `preset`              | str or None       | `None`         | named physics preset laid beneath `rod`/`fluid`/`ground`/`integrator`, field by field; `"thesis"`: the sources' setting (no damping, Kelasidi added mass, backward Euler), whose closed-loop results depend on the step (docs/model.md §5a) |
    | `rod`                 | dict or `Rod`     | `Rod()`        | the body (docs/model.md §9): N, edge length and mass, a, b, E, damping_bend, damping_stretch; `refine`: the same robot with that many nodes (`Rod.refined`) |
    | `fluid`               | dict or `Fluid`   | `Fluid()`      | water: rho, C_f, C_D, C_A                                                   |
    | `ground`              | dict or `Ground`  | `Ground()`     | unused in water; kept so one YAML file can describe both settings           |
    | `integrator`          | dict or `Integrator` | `Integrator()` | SDIRK2 (second order) at h = 0.01 s by default (docs/model.md §5a)           |
    | `dt`                  | float or None     | `None`         | control step (s), a multiple of `integrator.h`; `None`: `integrator.h`      |
    | `max_curvature_rate`  | float             | `2 pi`         | curvature rate (1/s) of action 1.0 (per node of the robot as designed)      |
    | `max_rest_curvature`  | float             | `4.0`          | bound on `|kbar|` (turning angle 127°)                                      |
    | `forward_reward_weight` | float           | `1.0`          | weight of *reward_forward* (per m/s)                                        |
    | `energy_cost_weight`  | float             | `1e-3`         | weight of *reward_energy* (per W)                                           |
    | `ctrl_cost_weight`    | float             | `1e-2`         | weight of *reward_ctrl*                                                     |
    | `failure_cost`        | float             | `10.0`         | penalty on a failure                                                        |
    | `reset_noise_scale`   | float             | `0.01`         | `s` of the Starting State                                                   |
    | `initial_shape`       | str               | `"straight"`   | `"straight"` or `"serpenoid"`                                               |
    | `serpenoid_alpha`     | float             | `pi/4`         | amplitude (rad) of the serpenoid initial body                               |
    | `serpenoid_delta`     | float or None     | `None`         | phase offset (rad) between nodes; `None`: `2 pi/(N-2)` (pi/4 for N = 10)    |
    | `start_on_gait`       | dict or None      | `None`         | start at rest on this serpenoid gait (alpha, omega, delta, gamma, psi0), no noise; see Starting State |
    | `goal_direction`      | float             | `0.0`          | goal direction (rad from +x)                                                |
    | `max_observed_speed`  | float             | `2.0`          | bound of `com_velocity_body` (m/s)                                          |
    | `randomize`           | dict or `Randomization` | off      | ranges `[low, high]` for E, E_bend, damping_bend, damping_stretch, rho, C_f, C_D, C_A (not the ground's) |

    ## Attributes
    Those of :class:`~soft_snake_gym.envs.base.SoftRobotEnv` (``sim``, ``task``, ``dt``, ``N``,
    ``total_mass``, ``observation_structure``, ``settings``, ``base_config``,
    ``goal_direction``, ``randomized``, ``metric_keys``).

    ## Version History
    * v0: initial version, on the PDER simulator of ``soft_snake_gym.physics``.
    """

    medium = "water"
    settings_class = SwimSettings
    env_id = "SoftEel-v0"
    medium_energy_key = "energy_fluid"

    def __init__(self, render_mode: str | None = None, config: Any = None, **kwargs: Any):
        """Build ``SoftEel-v0`` (keywords in the class docstring)."""
        super().__init__(render_mode=render_mode, config=config, **kwargs)

    def _setup_task(self) -> None:
        s = self.settings
        rod = self.base_config.rod
        self.max_curvature_rate = float(s.max_curvature_rate) * rod.edge_ratio
        self.max_rest_curvature = float(s.max_rest_curvature) * rod.edge_ratio
        n = self.N - 2
        alpha, delta, _ = serpenoid_on_nodes(s.serpenoid_alpha, s.serpenoid_delta, self.N, rod.design_nodes)
        self._kbar_initial = np.zeros(n)
        self._lbar_initial = np.full(self.N - 1, rod.edge_length)
        if s.initial_shape == "serpenoid":
            psi = serpenoid_phase(0.0, n, 0.0, delta)
            self._kbar_initial = serpenoid(psi, 0.0, alpha)[0]
            if np.abs(self._kbar_initial).max() > self.max_rest_curvature:
                raise ValueError(
                    f"serpenoid_alpha = {s.serpenoid_alpha!r} gives rest curvatures up to "
                    f"{np.abs(self._kbar_initial).max():.3f}, beyond max_rest_curvature = "
                    f"{self.max_rest_curvature!r}; lower the amplitude or raise the bound"
                )
        self._on_gait = s.start_on_gait is not None
        if self._on_gait:
            self._kbar_initial = self._gait_start_curvature(s.start_on_gait)

    def _gait_start_curvature(self, gait: SerpenoidParams) -> np.ndarray:
        """``kappa_des`` of ``gait`` at t = 0, (N-2,), checked against the env's bounds."""
        n = self.N - 2
        rod = self.base_config.rod
        alpha, delta, gamma = serpenoid_on_nodes(gait.alpha, gait.delta, self.N, rod.design_nodes, gait.gamma)
        kappa = serpenoid(serpenoid_phase(0.0, n, gait.omega, delta, gait.psi0), gait.omega, alpha, gamma)[0]
        if np.abs(kappa).max() > self.max_rest_curvature:
            raise ValueError(
                f"start_on_gait = {gait!r} has curvatures up to {np.abs(kappa).max():.3f} at t = 0, "
                f"beyond max_rest_curvature = {self.max_rest_curvature!r}; lower alpha or gamma or "
                "raise the bound"
            )
        if polyline_crosses(body_from_curvature(kappa, np.ones(n + 1))):
            limit = max_serpenoid_amplitude(self.N, delta, gamma)
            raise ValueError(
                f"start_on_gait alpha = {gait.alpha!r} makes a self-intersecting body at t = 0 "
                f"(delta = {delta:.4g}, N = {self.N}); keep alpha below {limit:.3f} rad"
            )
        return kappa

    def _build_spaces(self) -> None:
        s = self.settings
        n = self.N - 2
        self.observation_structure = {
            "kappa": n,
            "kappa_dot": n,
            "kbar": n,
            "com_velocity_body": 2,
            "goal_direction_body": 2,
        }
        high = np.concatenate(
            [
                np.full(n, 2.0 * self.max_rest_curvature),
                np.full(n, 4.0 * self.max_curvature_rate),
                np.full(n, self.max_rest_curvature),
                np.full(2, s.max_observed_speed),
                np.ones(2),
            ]
        ).astype(np.float32)
        self.observation_space = Box(-high, high, dtype=np.float32)
        self.action_space = Box(-1.0, 1.0, (n,), dtype=np.float32)

    def _action_params(self) -> tuple[int, float, float, float, int]:
        k = self.max_rest_curvature
        return T.SWIM, self.max_curvature_rate, -k, k, T.ENERGY_ACTUATOR

    def _start_body(self, rng: np.random.Generator) -> None:
        lbar = self._lbar_initial
        if self._on_gait:  # exactly on the gait, at rest, no noise
            x = body_from_curvature(self._kbar_initial, lbar)
            self.sim.start(x, np.zeros_like(x), self._kbar_initial, lbar)
            return
        self.sim.start_near_rest(self._kbar_initial, lbar, rng, self.settings.reset_noise_scale)

    def _check_options(self, body: dict[str, np.ndarray]) -> None:
        kbar = body.get("kbar")
        if kbar is not None and kbar.shape == (self.N - 2,) and np.abs(kbar).max() > self.max_rest_curvature:
            raise ValueError(
                f"reset option kbar reaches |kbar| = {np.abs(kbar).max():.4g}, beyond "
                f"max_rest_curvature = {self.max_rest_curvature!r}; keep it within that bound"
            )

    def _shape_views(self, raw: np.ndarray, shape: np.ndarray) -> dict[str, np.ndarray]:
        return {"kappa": raw[..., : self.N - 2], "kbar": shape}
