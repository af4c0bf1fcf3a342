"""The task layer of one robot as numba kernels: action to inputs, physics step, observation,
reward terms and running metrics, in one compiled call.

``SoftEel-v0`` and ``SoftWorm-v0`` call :func:`robot_step` for their one robot; the batched
vector env (:mod:`soft_snake_gym.envs.vector`) calls :func:`batch_step`, a ``prange`` loop of
the same :func:`robot_step` over robots, so a robot's results are bitwise the same in both.
Resets stay in Python (seeded noise, randomization draws) and end with :func:`robot_reset`.

Per robot, besides the simulator's arrays (``q, v, kbar, lbar, prm, buf, J, ibuf, out``):

- ``tp`` (``N_TP``,) float64, the task's constants at indices ``T_*`` (kind, action scale and
  bounds, control step, goal, reward weights, total mass);
- ``rs`` (``N_RS``,) float64, the task's state and the last step's results at ``R_*``
  (status, centre of mass, heading, powers, forward speed, reward terms, reward) and the
  running episode metrics at ``M_*`` (docs/model.md §8);
- ``act`` (n_act,) the action (clipped in place), ``uk`` (N-2,), ``ul`` (N-1,) the inputs,
  ``w`` (N,) the mass fractions, ``low``/``high`` the observation bounds, ``raw`` (float64,
  unclipped) and ``obs`` (float32) the observation.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit, prange

from soft_snake_gym.envs import observe
from soft_snake_gym.physics import kernels as K
from soft_snake_gym.physics.cache import drop_stale_cache

__all__ = ["robot_step", "robot_reset", "batch_step", "batch_step_serial", "allocate_task", "METRIC_KEYS",
           "TERM_KEYS"]

drop_stale_cache(
    __file__, [K.__file__, str(Path(K.__file__).with_name("banded.py")), observe.__file__]
)

G = 9.81
"""Gravity used by the cost of transport (docs/model.md §8) [m/s^2]."""

# --- task constants tp ------------------------------------------------------------------------
SWIM, INCH = 0, 1
ENERGY_ACTUATOR, ENERGY_MEDIUM = 0, 1
(T_KIND, T_SCALE, T_LO, T_HI, T_DT, T_NSUB, T_GOAL, T_GCOS, T_GSIN, T_WF, T_WE, T_WC, T_FAIL,
 T_ESRC, T_MASS) = range(15)
N_TP = 15

# --- task state rs ----------------------------------------------------------------------------
(R_STATUS, R_COMX, R_COMY, R_COM0X, R_COM0Y, R_HEADING, R_P_ACT, R_P_MED, R_FWD, R_EPOW, R_ASQ,
 R_RF, R_RE, R_RC, R_RFAIL, R_REWARD) = range(16)
M0 = 16
(M_AVG, M_DIST, M_DISP, M_DUR, M_COT, M_EMED, M_EACT, M_WACT) = range(M0, M0 + 8)
N_RS = M0 + 8

BAD_ACTION = -1
"""Status of a step refused because the action has a non-finite entry (nothing was stepped)."""

TERM_KEYS = ("reward_forward", "reward_energy", "reward_ctrl", "reward_failure")
"""Names of the reward terms ``rs[R_RF:R_RFAIL+1]``."""

METRIC_KEYS = ("average_speed", "distance", "displacement", "duration", "cost_of_transport",
               None, "energy_actuator", "actuator_work")
"""Names of the metrics ``rs[M_AVG:]``; ``None`` is the medium's energy (``energy_fluid`` or
``energy_friction``)."""


def allocate_task(N: int, n_act: int, n_obs: int, batch: tuple[int, ...] = ()) -> dict[str, np.ndarray]:
    """The task arrays of ``batch`` robots of N nodes (see the module docstring)."""
    return {
        "tp": np.zeros(batch + (N_TP,)),
        "rs": np.zeros(batch + (N_RS,)),
        "act": np.zeros(batch + (n_act,)),
        "uk": np.zeros(batch + (N - 2,)),
        "ul": np.zeros(batch + (N - 1,)),
        "w": np.zeros(batch + (N,)),
        "low": np.zeros(batch + (n_obs,)),
        "high": np.zeros(batch + (n_obs,)),
        "raw": np.zeros(batch + (n_obs,)),
        "obs": np.zeros(batch + (n_obs,), dtype=np.float32),
    }


@njit(cache=True, error_model="numpy")
def _observe(q, v, kbar, lbar, prm, ibuf, w, tp, low, high, raw, obs):
    if int(tp[T_KIND]) == SWIM:
        return observe.swim_observation(q, v, kbar, w, tp[T_GOAL], low, high, raw, obs)
    ground = int(prm[K.P_MEDIUM]) == K.MEDIUM_GROUND
    return observe.inch_observation(q, v, lbar, ibuf[K.I_FRICTION], ground, w, low, high, raw, obs)


@njit(cache=True, error_model="numpy")
def _com(q, w):
    """Centre of mass of flat interleaved positions ``q`` with mass fractions ``w``."""
    x = 0.0
    y = 0.0
    for i in range(w.size):
        x += w[i] * q[2 * i]
        y += w[i] * q[2 * i + 1]
    return x, y


@njit(cache=True, error_model="numpy")
def _metrics(out, prm, tp, rs):
    """Episode averages of docs/model.md §8 from the accumulated energies and the centre of mass."""
    dx = rs[R_COMX] - rs[R_COM0X]
    dy = rs[R_COMY] - rs[R_COM0Y]
    distance = dx * tp[T_GCOS] + dy * tp[T_GSIN]
    duration = out[K.O_NSTEPS] * prm[K.P_H]
    ground = int(prm[K.P_MEDIUM]) == K.MEDIUM_GROUND
    rs[M_AVG] = distance / duration if duration > 0.0 else 0.0
    rs[M_DIST] = distance
    rs[M_DISP] = math.hypot(dx, dy)
    rs[M_DUR] = duration
    rs[M_COT] = out[K.O_E_ACT] / (tp[T_MASS] * G * distance) if distance > 0.0 else math.inf
    rs[M_EMED] = out[K.O_E_FRICTION] if ground else out[K.O_E_FLUID]
    rs[M_EACT] = out[K.O_E_ACT]
    rs[M_WACT] = out[K.O_W_ACT]


@njit(cache=True, error_model="numpy")
def robot_reset(q, v, kbar, lbar, prm, ibuf, out, w, tp, low, high, raw, obs, rs):
    """After the simulator's reset: the episode starts here (centre of mass, zero powers and
    rewards, metrics, observation)."""
    rs[:] = 0.0
    x, y = _com(q, w)
    rs[R_COMX] = rs[R_COM0X] = x
    rs[R_COMY] = rs[R_COM0Y] = y
    _metrics(out, prm, tp, rs)
    rs[R_HEADING] = _observe(q, v, kbar, lbar, prm, ibuf, w, tp, low, high, raw, obs)


@njit(cache=True, error_model="numpy")
def robot_step(act, q, v, kbar, lbar, prm, buf, J, ibuf, out, uk, ul, w, tp, low, high, raw, obs, rs):
    """One control step of one robot. Returns the status (``K.OK``, a failure code, or
    :data:`BAD_ACTION` if ``act`` has a non-finite entry, in which case nothing changes).

    Clips ``act`` to [-1, 1] and turns it into rates (curvature rates for a swimmer, length
    rates for an inchworm) cut at the rest-shape bounds; advances ``tp[T_NSUB]`` integrator
    steps; on success updates the centre of mass, powers, observation and metrics. On a failure
    they keep their last valid values. The reward terms and the reward are written either way.
    """
    dt = tp[T_DT]
    if int(tp[T_KIND]) == SWIM:
        sq = observe.scale_rates(act, tp[T_SCALE], kbar, tp[T_LO], tp[T_HI], dt, uk)
    else:
        sq = observe.scale_rates(act, tp[T_SCALE], lbar, tp[T_LO], tp[T_HI], dt, ul)
    if sq != sq:
        return BAD_ACTION
    ground = int(prm[K.P_MEDIUM]) == K.MEDIUM_GROUND
    e_act0 = out[K.O_E_ACT]
    w_act0 = out[K.O_W_ACT]
    e_med0 = out[K.O_E_FRICTION] if ground else out[K.O_E_FLUID]
    nsub = int(tp[T_NSUB])
    status = K.simulate(q, v, kbar, lbar, uk, ul, prm, buf, J, ibuf, out, nsub)
    rs[R_STATUS] = status
    rs[R_ASQ] = sq
    if status == K.OK:
        x, y = _com(q, w)
        fwd = ((x - rs[R_COMX]) * tp[T_GCOS] + (y - rs[R_COMY]) * tp[T_GSIN]) / dt
        d_med = (out[K.O_E_FRICTION] if ground else out[K.O_E_FLUID]) - e_med0
        if int(tp[T_ESRC]) == ENERGY_MEDIUM:
            epow = d_med / dt
        else:
            epow = (out[K.O_E_ACT] - e_act0) / dt
        if nsub == 1:  # the simulator's own figures for its one step
            rs[R_P_ACT] = out[K.O_P_ACT]
            rs[R_P_MED] = out[K.O_P_FRICTION] if ground else out[K.O_P_FLUID]
        else:  # averages over the control step
            rs[R_P_ACT] = (out[K.O_W_ACT] - w_act0) / dt
            rs[R_P_MED] = d_med / dt
        rs[R_COMX] = x
        rs[R_COMY] = y
        rs[R_HEADING] = _observe(q, v, kbar, lbar, prm, ibuf, w, tp, low, high, raw, obs)
        _metrics(out, prm, tp, rs)
    else:
        fwd = 0.0
        epow = 0.0
    rs[R_FWD] = fwd
    rs[R_EPOW] = epow
    rs[R_RF] = tp[T_WF] * fwd
    rs[R_RE] = -tp[T_WE] * epow
    rs[R_RC] = -tp[T_WC] * sq
    rs[R_RFAIL] = -tp[T_FAIL] if status != K.OK else 0.0
    rs[R_REWARD] = rs[R_RF] + rs[R_RE] + rs[R_RC] + rs[R_RFAIL]
    return status


@njit(cache=True, parallel=True, error_model="numpy")
def batch_step(active, act, q, v, kbar, lbar, prm, buf, J, ibuf, out, uk, ul, w, tp, low, high,
               raw, obs, rs, status):
    """:func:`robot_step` for every robot ``i`` with ``active[i]`` (arrays stacked on a leading
    robot axis), spread over numba's threads; robot ``i``'s status into ``status[i]``."""
    for i in prange(q.shape[0]):
        if active[i]:
            status[i] = robot_step(act[i], q[i], v[i], kbar[i], lbar[i], prm[i], buf[i], J[i],
                                   ibuf[i], out[i], uk[i], ul[i], w[i], tp[i], low[i], high[i],
                                   raw[i], obs[i], rs[i])


@njit(cache=True, error_model="numpy")
def batch_step_serial(active, act, q, v, kbar, lbar, prm, buf, J, ibuf, out, uk, ul, w, tp, low, high,
                      raw, obs, rs, status):
    """:func:`batch_step` on the calling thread alone (no thread-pool launch: for one thread)."""
    for i in range(q.shape[0]):
        if active[i]:
            status[i] = robot_step(act[i], q[i], v[i], kbar[i], lbar[i], prm[i], buf[i], J[i],
                                   ibuf[i], out[i], uk[i], ul[i], w[i], tp[i], low[i], high[i],
                                   raw[i], obs[i], rs[i])
