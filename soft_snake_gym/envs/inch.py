"""``SoftWorm-v0``: the same robot on the ground, inching by moving its rest lengths."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from gymnasium.spaces import Box

from soft_snake_gym.envs import task as T
from soft_snake_gym.envs.base import SoftRobotEnv
from soft_snake_gym.envs.settings import BaseSettings
from soft_snake_gym.params import check_number

__all__ = ["InchEnv", "InchSettings"]


@dataclass(frozen=True)
class InchSettings(BaseSettings):
    """Constructor keywords of :class:`InchEnv` (the table in its docstring)."""

    forward_reward_weight: float = 10.0
    energy_cost_weight: float = 1e-3
    ctrl_cost_weight: float = 1e-3
    max_length_rate: float = 0.3
    rest_length_limits: tuple[float, float] = (0.5, 1.5)
    energy_source: Literal["friction", "actuator"] = "friction"

    def __post_init__(self) -> None:
        """Check the settings of :class:`InchEnv` on top of the shared ones."""
        super().__post_init__()
        check_number("InchSettings.max_length_rate", self.max_length_rate, 0.0, lo_open=True)
        lim = tuple(self.rest_length_limits)
        object.__setattr__(self, "rest_length_limits", lim)
        if len(lim) != 2 or not (0.0 < lim[0] <= 1.0 <= lim[1]):
            raise ValueError(
                f"InchSettings.rest_length_limits = {list(lim)!r} must be [low, high] fractions of the "
                "edge length with 0 < low <= 1 <= high"
            )
        if self.energy_source not in ("friction", "actuator"):
            raise ValueError(
                f"InchSettings.energy_source = {self.energy_source!r}; use 'friction' or 'actuator'"
            )


class InchEnv(SoftRobotEnv):
    r"""A soft worm that inches on the ground by stretching: ``SoftWorm-v0``.

    ## Description
    The same planar discrete elastic rod as ``SoftEel-v0`` (N = 10 nodes, 9 edges of 0.18 m,
    0.8 kg each) lying on a flat floor with Karnopp stick-slip friction (``mu_s = 1.15``,
    ``mu_d = 0.8``; docs/model.md §5), its rest shape straight. The agent moves the rest lengths
    ``lbar`` of the 9 edges; a peristaltic compression pulse travelling from tail to head
    (``soft_snake_gym.gaits.pulse_wave``, eps = 0.3, omega = 2 pi rad/s, delta_l = 2 pi/9,
    duty 0.6: the ``inching`` baseline) inches forward at about 0.127 m/s, while a sinusoidal
    wave that changes every edge at once barely moves it. The task is to move along the goal
    direction (+x by default, the head ahead).

    ## Action Space
    A `Box(-1, 1, (N-1,), float32)`: the commanded length rates ``u_l = max_length_rate *
    action`` [m/s] of the edges, held over the control step. The rest lengths follow them
    through the length actuators' first-order lag ``Rod.length_lag`` (default 0.05 s;
    ``tau d(lbar_dot)/dt = u_l - lbar_dot``, docs/model.md §3), so ``lbar`` moves smoothly and
    ``lbar_dot`` approaches ``u_l`` within about 3 tau; the edge length rates observed follow
    ``lbar_dot`` closely (stretching is stiff). Actions outside [-1, 1] are clipped; a NaN or a
    wrong shape raises ``ValueError``. A rate that would carry ``lbar`` outside
    ``rest_length_limits`` (fractions of the edge length) is cut so that ``lbar`` stops at the
    bound (early enough that the lag does not carry it past). The default
    ``max_length_rate = 0.3`` m/s covers the inching wave's peak rate ``0.5 l0 eps omega =
    0.17`` m/s at eps = 0.3, omega = 2 pi, with room for feedback. On a refined rod
    (``rod={"refine": N}``) ``max_length_rate`` (as given, that of the robot as designed) is
    scaled by ``Rod.edge_ratio = l / l_d``: the same strain rate at action 1.0 whatever N.

    ## Observation Space
    A `Box(low, high, (4N-1,), float32)` in this order (``observation_structure``); values
    beyond the bounds are clipped (``l0`` = edge length, ``[lo, hi]`` = ``rest_length_limits``):

    | Block              | Size | Bounds                   | Meaning (unit)                                            |
    |--------------------|------|--------------------------|-----------------------------------------------------------|
    | edge_lengths       | N-1  | [0, 2 hi l0]             | current edge lengths (m)                                  |
    | edge_length_rates  | N-1  | ±10 max_length_rate      | their rates (m/s)                                         |
    | lbar               | N-1  | [lo l0, hi l0]           | rest lengths (m)                                          |
    | stuck              | N    | {0, 1}                   | 1 where the node stuck to the ground in the last step     |
    | com_velocity_body  | 2    | ±max_observed_speed      | centre-of-mass velocity along the heading, lateral (m/s)  |

    ## Rewards
    ``reward = reward_forward + reward_energy + reward_ctrl + reward_failure``, each in ``info``:

    - *reward_forward* = ``forward_reward_weight * forward_speed``: centre-of-mass
      displacement along the goal direction over the step, divided by ``dt`` (m/s).
    - *reward_energy* = ``-energy_cost_weight * P``: with ``energy_source="friction"`` (default)
      ``P`` is the power lost to friction (the land energy metric of docs/model.md §5), with
      ``"actuator"`` the absolute actuator power (docs/model.md §3), averaged over the step (W).
    - *reward_ctrl* = ``-ctrl_cost_weight * ||action||^2`` (normalized action).
    - *reward_failure* = ``-failure_cost`` on the step that ends the episode by a failure.

    ## Starting State
    A straight body along +x (head ahead, whatever ``goal_direction``), bent by curvatures
    drawn from U(-s, s) at each interior node and turned by U(-s, s) rad, with rest lengths ``l0 (1 + U(-s, s))`` that the
    body matches (``s = reset_noise_scale``), rest shape straight, at rest, centre of mass at
    the origin. ``reset(options={"x", "v", "kbar", "lbar"})`` sets the initial body exactly;
    ``options={"goal_direction": angle}`` sets the episode's goal. With ``randomize``, the
    physics is drawn anew at each reset, the values in ``info["randomized"]``.

    ## Episode End
    ### Termination
    A failed physics step (non-finite state, self-intersection, runaway stretch, a Newton step
    that does not converge); ``info["failure"]`` names the reason; the observation, the state
    entries of ``info`` and ``info["metrics"]`` are those of the last valid state.
    ### Truncation
    1000 steps (10 s at the default ``dt``), by ``TimeLimit`` through ``gym.make``.

    ## Info
    Every step: ``forward_speed`` (m/s), ``x_position``, ``y_position``, ``heading``, ``time``,
    ``friction_power``, ``actuator_power`` (signed; W), ``edge_lengths``, ``lbar``, ``stuck``,
    ``newton_iterations``, every ``reward_<term>``, ``failure`` and ``metrics`` (running episode
    summary: ``average_speed``, ``distance``, ``displacement``, ``duration``,
    ``cost_of_transport``, ``energy_friction``, ``energy_actuator``, ``actuator_work``) and
    ``energy``, the episode's energy ledger (as for ``SoftEel-v0``; here the ground takes
    ``friction_dissipation``).

    ## Arguments
    ```python
    env = gym.make("SoftWorm-v0", max_length_rate=0.4, ground={"mu_s": 0.9, "mu_d": 0.6})
    env = gym.make("SoftWorm-v0", config="softworm")  # a shipped config by name, or a YAML path
    env = gym.make("SoftWorm-v0", preset="thesis")  # the sources' physics
    ```

    Keywords given explicitly override those from ``config``, which override the ``preset``.

    | Parameter             | Type              | Default        | Description                                                                 |
    |-----------------------|-------------------|----------------|-----------------------------------------------------------------------------|
    | `config`              | str or Path       | `None`         | YAML file of any keywords below (a `medium: ground` key is accepted)        |
    | `render_mode`         | str               | `None`         | `"rgb_array"` (headless image) or `"human"` (a window; needs a display)     |
    | `preset`              | str or None       | `None`         | named physics preset laid beneath `rod`/`fluid`/`ground`/`integrator`, field by field; `"thesis"`: the sources' setting (no damping, Kelasidi added mass, backward Euler), whose closed-loop results depend on the step (docs/model.md §5a) |
    | `rod`                 | dict or `Rod`     | `Rod()`        | the body (docs/model.md §9); `refine`: the same robot with that many nodes       |
    | `fluid`               | dict or `Fluid`   | `Fluid()`      | unused on the ground                                                        |
    | `ground`              | dict or `Ground`  | `Ground()`     | friction: mu_s, mu_d, V_tol, g                                              |
    | `integrator`          | dict or `Integrator` | `Integrator()` | backward Euler at h = 0.01 s by default                                  |
    | `dt`                  | float or None     | `None`         | control step (s), a multiple of `integrator.h`; `None`: `integrator.h`      |
    | `max_length_rate`     | float             | `0.3`          | length rate (m/s) of action 1.0 (per edge of the robot as designed)         |
    | `rest_length_limits`  | [float, float]    | `[0.5, 1.5]`   | bounds of `lbar` as fractions of the edge length                            |
    | `energy_source`       | str               | `"friction"`   | `"friction"` or `"actuator"`: the power charged by *reward_energy*          |
    | `forward_reward_weight` | float           | `10.0`         | weight of *reward_forward* (per m/s)                                        |
    | `energy_cost_weight`  | float             | `1e-3`         | weight of *reward_energy* (per W)                                           |
    | `ctrl_cost_weight`    | float             | `1e-3`         | weight of *reward_ctrl*                                                     |
    | `failure_cost`        | float             | `10.0`         | penalty on a failure                                                        |
    | `reset_noise_scale`   | float             | `0.01`         | `s` of the Starting State                                                   |
    | `goal_direction`      | float             | `0.0`          | goal direction (rad from +x)                                                |
    | `max_observed_speed`  | float             | `2.0`          | bound of `com_velocity_body` (m/s)                                          |
    | `randomize`           | dict or `Randomization` | off      | ranges `[low, high]` for E, E_bend, damping_bend, damping_stretch, length_lag, mu_s, mu_d (every mu_d draw <= every mu_s draw; not the fluid's) |

    ## Attributes
    Those of :class:`~soft_snake_gym.envs.base.SoftRobotEnv` (``sim``, ``task``, ``dt``, ``N``,
    ``total_mass``, ``observation_structure``, ``settings``, ``base_config``,
    ``goal_direction``, ``randomized``, ``metric_keys``).

    ## Version History
    * v0: initial version, on the PDER simulator of ``soft_snake_gym.physics``.
    """

    medium = "ground"
    settings_class = InchSettings
    env_id = "SoftWorm-v0"
    medium_energy_key = "energy_friction"
    medium_power_key = "friction_power"
    shape_key = "lbar"
    shape_flags = ("stuck",)  # held as exactly 0.0 or 1.0: astype(bool) takes half the time of "> 0.5"

    def __init__(self, render_mode: str | None = None, config: Any = None, **kwargs: Any):
        """Build ``SoftWorm-v0`` (keywords in the class docstring)."""
        super().__init__(render_mode=render_mode, config=config, **kwargs)

    def _setup_task(self) -> None:
        s = self.settings
        self.max_length_rate = float(s.max_length_rate) * self.base_config.rod.edge_ratio
        l0 = self.base_config.rod.edge_length
        self.lbar_limits = (s.rest_length_limits[0] * l0, s.rest_length_limits[1] * l0)
        self._kbar_initial, self._lbar_initial = np.zeros(self.N - 2), np.full(self.N - 1, l0)  # straight

    def _build_spaces(self) -> None:
        s = self.settings
        m = self.N - 1
        l0 = self.base_config.rod.edge_length
        lo, hi = s.rest_length_limits[0] * l0, s.rest_length_limits[1] * l0
        self.observation_structure = {
            "edge_lengths": m,
            "edge_length_rates": m,
            "lbar": m,
            "stuck": self.N,
            "com_velocity_body": 2,
        }
        low = np.concatenate(
            [
                np.zeros(m),
                np.full(m, -10.0 * self.max_length_rate),
                np.full(m, lo),
                np.zeros(self.N),
                np.full(2, -s.max_observed_speed),
            ]
        ).astype(np.float32)
        high = np.concatenate(
            [
                np.full(m, 2.0 * hi),
                np.full(m, 10.0 * self.max_length_rate),
                np.full(m, hi),
                np.ones(self.N),
                np.full(2, s.max_observed_speed),
            ]
        ).astype(np.float32)
        self.observation_space = Box(low, high, dtype=np.float32)
        self.action_space = Box(-1.0, 1.0, (m,), dtype=np.float32)

    def _action_params(self) -> tuple[int, float, float, float, int]:
        lo, hi = self.lbar_limits
        energy = T.ENERGY_MEDIUM if self.settings.energy_source == "friction" else T.ENERGY_ACTUATOR
        return T.INCH, self.max_length_rate, lo, hi, energy

    def _start_body(self, rng: np.random.Generator) -> None:
        scale = self.settings.reset_noise_scale
        self.sim.start_near_rest(
            self._kbar_initial, self._lbar_initial, rng, scale, lbar_limits=self.lbar_limits
        )

    def _check_options(self, body: dict[str, np.ndarray]) -> None:
        lbar = body.get("lbar")
        lo, hi = self.lbar_limits
        if lbar is not None and lbar.shape == (self.N - 1,) and (lbar.min() < lo or lbar.max() > hi):
            raise ValueError(
                f"reset option lbar spans [{lbar.min():.4g}, {lbar.max():.4g}] m, outside "
                f"rest_length_limits [{lo:.4g}, {hi:.4g}] m; keep it within those bounds"
            )

    def _shape_views(self, raw: np.ndarray, shape: np.ndarray) -> dict[str, np.ndarray]:
        m = self.N - 1
        return {"edge_lengths": raw[..., :m], "lbar": shape, "stuck": raw[..., 3 * m : 4 * m + 1]}
