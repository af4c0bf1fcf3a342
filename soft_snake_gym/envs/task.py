"""The task layer of one robot as numba kernels.

Action to inputs, physics step, observation, reward terms and running metrics, in one compiled call.

``SoftEel-v0`` and ``SoftWorm-v0`` call :func:`robot_step` for their one robot (through
:func:`robot_step_blocks`, which takes the arrays as the blocks they are views of); the batched
vector env (:mod:`soft_snake_gym.envs.vector`) runs :func:`step_units` on each of its threads,
the same :func:`robot_step` over a run of robots, so a robot's results are bitwise the same in
both. :func:`batch_step` is that ``prange`` loop without the env's bookkeeping around it.
Resets stay in Python (seeded noise, randomization draws) and end with :func:`robot_reset`.

Per robot, the kernels take the simulator's :class:`~soft_snake_gym.physics.SimArrays` and the
task's :class:`TaskArrays` (both stacked on a leading robot axis for :func:`batch_step`); Python
passes them as plain tuples, which the kernels name on entry, or as their blocks, over which the
kernels make the views again (see :mod:`soft_snake_gym.physics.layout`).
Inside the kernels the task's scalars sit at named indices (``T_*`` in ``tp``, ``R_*`` and
``M_*`` in ``rs``), as the simulator's do; Python reads them by name through the envs'
``info`` displays (``SoftRobotEnv._info_displays``) and :func:`episode_metrics`.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit, prange

from soft_snake_gym.envs import observe
from soft_snake_gym.physics import banded, forces, geometry, lanes, stepper
from soft_snake_gym.physics import layout as L
from soft_snake_gym.physics.cache import drop_stale_cache
from soft_snake_gym.physics.layout import SimArrays

__all__ = [
    "TaskArrays",
    "allocate_task",
    "robot_step",
    "robot_step_blocks",
    "robot_reset",
    "batch_step",
    "batch_step_serial",
    "step_units",
    "units",
    "first_robot",
    "episode_metrics",
    "METRIC_KEYS",
    "NAV_METRIC_KEYS",
    "NAV_TERM_KEYS",
    "TERM_KEYS",
]

KERNEL_SOURCES = [m.__file__ for m in (banded, forces, geometry, L, lanes, stepper, observe)]
"""The files whose kernels this module's kernels call: their cached code embeds those kernels."""
drop_stale_cache(__file__, KERNEL_SOURCES)

# --- task constants tp ------------------------------------------------------------------------
SWIM, INCH = 0, 1
ENERGY_ACTUATOR, ENERGY_MEDIUM = 0, 1
(
    T_KIND,
    T_SCALE,
    T_LO,
    T_HI,
    T_DT,
    T_NSUB,
    T_GOAL,
    T_GCOS,
    T_GSIN,
    T_WF,
    T_WE,
    T_WC,
    T_FAIL,
    T_ESRC,
    T_MASS,
    T_TASK,
    T_TX,
    T_TY,
    T_RADIUS,
    T_BONUS,
    T_WXTE,
    T_NPATH,
) = range(22)
N_TP = 22

# --- what the robot is asked to do: tp[T_TASK] ------------------------------------------------
TASK_DIRECTION, TASK_GOAL, TASK_PATH = 0, 1, 2
"""Swim along a fixed direction (``SoftEel-v0``), reach a target point, follow a path."""
SEARCH_WINDOW = 16
"""Segments searched on either side of the last closest one when the robot follows a path."""

# --- task state rs ----------------------------------------------------------------------------
# Below R_FWD the state that an info reports after a reset too; from R_FWD on what a step makes,
# which a batched info gives as 0 for a robot that did not step (envs.vector._snapshot).
(
    R_STATUS,
    R_COMX,
    R_COMY,
    R_COM0X,
    R_COM0Y,
    R_HEADING,
    R_P_ACT,
    R_P_MED,
    R_NAV,
    R_SUCCESS,
    R_FWD,
    R_EPOW,
    R_ASQ,
    R_RF,
    R_RE,
    R_RC,
    R_RFAIL,
    R_RXTE,
    R_RSUCC,
    R_REWARD,
    R_S,
    R_S0,
    R_SEG,
    R_XINT,
) = range(24)
M0 = 24
(M_AVG, M_DIST, M_DISP, M_DUR, M_COT, M_EMED, M_EACT, M_WACT, M_N1, M_N2, M_N3) = range(M0, M0 + 11)
N_RS = M0 + 11

BAD_ACTION = -1
"""Status of a step refused because the action has a non-finite entry (nothing was stepped)."""

_IDLE = -2  # block_step's state of a lane whose robot is not stepped

TERM_KEYS = ("reward_forward", "reward_energy", "reward_ctrl", "reward_failure")
"""Names of the reward terms ``rs[R_RF:R_RFAIL+1]``."""

NAV_TERM_KEYS = ("reward_cross_track", "reward_success")
"""Names of the navigation tasks' extra reward terms ``rs[R_RXTE:R_RSUCC+1]``."""

NAV_METRIC_KEYS = {
    TASK_GOAL: ("success", "time_to_goal", "target_distance"),
    TASK_PATH: ("cross_track_error", "final_cross_track_error"),
}
"""Names of the navigation tasks' extra metrics ``rs[M_N1:]``, after :data:`METRIC_KEYS`: whether
the target was reached (0/1), when [s] (inf until then) and the distance left to it [m]; the
path's cross-track error [m], its mean over the episode and its value now (absolute)."""

METRIC_KEYS = (
    "average_speed",
    "distance",
    "displacement",
    "duration",
    "cost_of_transport",
    None,
    "energy_actuator",
    "actuator_work",
)
"""Names of the metrics ``rs[M_AVG:]``; ``None`` is the medium's energy (``energy_fluid`` or
``energy_friction``)."""


class TaskArrays(NamedTuple):
    """The task's arrays of one robot (or of ``n``, stacked on a leading axis), as the task kernels take them.

    The float64 arrays are views of one block per robot, ``f`` (:func:`task_offsets`), as the
    simulator's are (see :mod:`~soft_snake_gym.physics.layout`); a pickled ``TaskArrays`` keeps
    them so.

    Attributes:
        tp: the task's constants at ``T_*`` (kind, action scale and bounds, control step, goal,
            reward weights, total mass), (N_TP,).
        rs: the task's state and the last step's results at ``R_*`` (status, centre of mass,
            heading, powers, forward speed, reward terms, reward) and the running episode
            metrics at ``M_*`` (docs/model.md §8), (N_RS,); read them by name in ``info``
            or with :func:`episode_metrics`.
        act: the action, clipped in place, (n_act,) [-].
        uk: curvature rates, (N-2,) [1/s].
        ul: rest-length rates, (N-1,) [m/s].
        w: mass fractions of the nodes, (N,) [-].
        low, high: bounds of the observation, (n_obs,).
        raw: the observation unclipped, float64, (n_obs,).
        obs: the observation, float32, (n_obs,) (not in ``f``).
        path: the path to follow as a polyline (``TASK_PATH``): rows ``(x, y, s)``, a vertex [m]
            and its arc length from the first one [m], (n_path, 3); the first segment extends
            backwards and the last forwards without end.
        f: the block the float64 arrays are views of, (``task_offsets(...)[-1]``,).
    """

    tp: np.ndarray
    rs: np.ndarray
    act: np.ndarray
    uk: np.ndarray
    ul: np.ndarray
    w: np.ndarray
    low: np.ndarray
    high: np.ndarray
    raw: np.ndarray
    obs: np.ndarray
    path: np.ndarray
    f: np.ndarray

    def row(self, i: int) -> TaskArrays:
        """Robot ``i`` of stacked arrays: views, so writes go to the batch."""
        return TaskArrays(*(a[i] for a in self))

    def __reduce__(self):
        """Pickle the blocks and rebuild the views on loading (numpy pickles a view as a copy of its own)."""
        return task_arrays_over, (self.f, self.obs, self.w.shape[-1], self.act.shape[-1], self.path.shape[-2])


@njit(cache=True, _nrt=False)
def task_offsets(N: int, n_act: int, n_obs: int, n_path: int) -> tuple[int, ...]:
    """Where ``rs``, ``act``, ``uk``, ``ul``, ``w``, ``low``, ``high``, ``raw``, ``path`` start in a robot's block ``f``, and its size.

    ``tp`` starts at 0. Compiled, so that the kernels and :func:`task_arrays_over` share it.
    """
    o_act = N_TP + N_RS
    o_uk = o_act + n_act
    o_ul = o_uk + N - 2
    o_w = o_ul + N - 1
    o_low = o_w + N
    o_path = o_low + 3 * n_obs
    return N_TP, o_act, o_uk, o_ul, o_w, o_low, o_low + n_obs, o_low + 2 * n_obs, o_path, o_path + 3 * n_path


@njit(cache=True, inline="always")
def task_views(f, obs, N, n_act, n_path):
    """One robot's :class:`TaskArrays` over its block ``f`` and its ``obs`` (compiled code), borrowed.

    As :func:`~soft_snake_gym.physics.layout.sim_views`: the views pay no reference counting.
    """
    f, obs = L.borrowed(f), L.borrowed(obs)
    o_rs, o_act, o_uk, o_ul, o_w, o_low, o_high, o_raw, o_path, end = task_offsets(N, n_act, obs.size, n_path)
    return TaskArrays(
        f[:o_rs],
        f[o_rs:o_act],
        f[o_act:o_uk],
        f[o_uk:o_ul],
        f[o_ul:o_w],
        f[o_w:o_low],
        f[o_low:o_high],
        f[o_high:o_raw],
        f[o_raw:o_path],
        obs,
        L.rows_of(f, o_path, n_path, 3),
        f,
    )


def task_arrays_over(f: np.ndarray, obs: np.ndarray, N: int, n_act: int, n_path: int) -> TaskArrays:
    """:class:`TaskArrays` of robots of N nodes over blocks ``f`` (..., size) and ``obs`` (..., n_obs), any leading axes."""
    lead, n_obs = f.shape[:-1], obs.shape[-1]
    o_rs, o_act, o_uk, o_ul, o_w, o_low, o_high, o_raw, o_path, end = task_offsets(N, n_act, n_obs, n_path)
    return TaskArrays(
        f[..., :o_rs],
        f[..., o_rs:o_act],
        f[..., o_act:o_uk],
        f[..., o_uk:o_ul],
        f[..., o_ul:o_w],
        f[..., o_w:o_low],
        f[..., o_low:o_high],
        f[..., o_high:o_raw],
        f[..., o_raw:o_path],
        obs,
        f[..., o_path:end].reshape(lead + (n_path, 3)),
        f,
    )


def allocate_task(N: int, n_act: int, n_obs: int, batch: tuple[int, ...] = (), n_path: int = 2) -> TaskArrays:
    """Zeroed :class:`TaskArrays` of ``batch`` robots of N nodes (paths of ``n_path`` vertices)."""
    size = task_offsets(N, n_act, n_obs, n_path)[-1]
    return task_arrays_over(
        np.zeros(batch + (size,)), np.zeros(batch + (n_obs,), dtype=np.float32), N, n_act, n_path
    )


def episode_metrics(r: Any, keys: tuple[str, ...]) -> dict[str, Any]:
    """The running episode metrics (docs/model.md §8) by name, from ``rs`` (a list, or its rows ``rs.T``).

    ``keys`` are :data:`METRIC_KEYS` with the medium's energy named.
    """
    # not strict: the slice is cut to the keys' length (the check cost a third of the call)
    return dict(zip(keys, r[M_AVG : M_AVG + len(keys)], strict=False))


@njit(cache=True, inline="always", error_model="numpy")
def _observe(s, t, curved):
    """The observation into ``t.obs``; returns the heading.

    ``s.buf[B_GEO]`` holds the edge geometry of ``q``, as every step and every state written from
    outside leave it (``stepper.ledger_energies``, which ``start_from_state`` calls too);
    ``curved``: a swimmer's curvatures and their rates are already in ``t.raw``.
    """
    if int(t.tp[T_KIND]) == SWIM:
        if int(t.tp[T_TASK]) != TASK_DIRECTION:  # the distance to the target or the cross-track error
            t.raw[t.raw.size - 1] = t.rs[R_NAV]
        w, goal = t.w, t.tp[T_GOAL]
        if curved:
            return observe.swim_observation_curved(s.q, s.v, s.kbar, w, goal, t.low, t.high, t.raw, t.obs)
        geo = s.buf[L.B_GEO : L.B_GEO + 2]
        return observe.swim_observation(s.q, s.v, s.kbar, w, goal, t.low, t.high, t.raw, t.obs, geo)
    ground = int(s.prm[L.P_MEDIUM]) == L.MEDIUM_GROUND
    geo = s.buf[L.B_GEO : L.B_GEO + 2]
    return observe.inch_observation(
        s.q, s.v, s.lbar, s.ibuf[L.I_FRICTION], ground, t.w, t.low, t.high, t.raw, t.obs, geo
    )


@njit(cache=True, error_model="numpy", _nrt=False)
def _com(q, w):
    """Centre of mass of flat interleaved positions ``q`` with mass fractions ``w``."""
    x = 0.0
    y = 0.0
    for i in range(w.size):
        x += w[i] * q[2 * i]
        y += w[i] * q[2 * i + 1]
    return x, y


@njit(cache=True, error_model="numpy", _nrt=False)
def _navigate(tp, rs, path, x, y, search_all):
    """Where the robot at ``(x, y)`` stands in a navigation task; sets the direction to steer.

    To a target (``TASK_GOAL``): ``rs[R_NAV]`` the distance to it [m], ``rs[R_S]`` its negative (so
    that progress is ``rs[R_S] - rs[R_S0]``), the goal direction ``tp[T_GOAL]`` the bearing of the
    target from ``(x, y)``. Along a path (``TASK_PATH``): the closest point of the polyline ``path``
    (among the segments within :data:`SEARCH_WINDOW` of the last closest one, or all if
    ``search_all``), ``rs[R_NAV]`` the signed cross-track error (positive with the path on the
    robot's right, looking along the path) [m], ``rs[R_S]`` the arc length of the closest point
    [m], ``rs[R_SEG]`` its segment, and the goal direction the segment's direction.
    """
    if int(tp[T_TASK]) == TASK_GOAL:
        dx = tp[T_TX] - x
        dy = tp[T_TY] - y
        d = math.hypot(dx, dy)
        rs[R_NAV] = d
        rs[R_S] = -d
        direction = math.atan2(dy, dx)
    else:
        nseg = int(tp[T_NPATH]) - 1
        lo, hi = 0, nseg
        if not search_all:
            k = int(rs[R_SEG])
            lo, hi = max(0, k - SEARCH_WINDOW), min(nseg, k + SEARCH_WINDOW + 1)
        best, kb, tb = math.inf, lo, 0.0
        for k in range(lo, hi):
            ux = path[k + 1, 0] - path[k, 0]
            uy = path[k + 1, 1] - path[k, 1]
            f = ((x - path[k, 0]) * ux + (y - path[k, 1]) * uy) / (ux * ux + uy * uy)
            if k > 0 and f < 0.0:  # the first segment extends backwards, the last forwards
                f = 0.0
            if k < nseg - 1 and f > 1.0:
                f = 1.0
            dist = math.hypot(x - path[k, 0] - f * ux, y - path[k, 1] - f * uy)
            if dist < best:
                best, kb, tb = dist, k, f
        ux = path[kb + 1, 0] - path[kb, 0]
        uy = path[kb + 1, 1] - path[kb, 1]
        length = math.hypot(ux, uy)
        cross = (ux * (y - path[kb, 1]) - uy * (x - path[kb, 0])) / length
        rs[R_NAV] = best if cross >= 0.0 else -best
        rs[R_S] = path[kb, 2] + tb * length
        rs[R_SEG] = kb
        direction = math.atan2(uy, ux)
    tp[T_GOAL] = direction
    tp[T_GCOS] = math.cos(direction)
    tp[T_GSIN] = math.sin(direction)


@njit(cache=True, error_model="numpy", _nrt=False)
def _metrics(out, prm, tp, rs):
    """Episode averages of docs/model.md §8 from the accumulated energies and the centre of mass.

    The distance is the progress toward the goal: along the goal direction, or, in a navigation
    task, toward the target or along the path (``rs[R_S] - rs[R_S0]``); the task's own metrics
    go to ``rs[M_N1:]`` (:data:`NAV_METRIC_KEYS`).
    """
    dx = rs[R_COMX] - rs[R_COM0X]
    dy = rs[R_COMY] - rs[R_COM0Y]
    task = int(tp[T_TASK])
    if task == TASK_DIRECTION:
        distance = dx * tp[T_GCOS] + dy * tp[T_GSIN]
    else:
        distance = rs[R_S] - rs[R_S0]
    duration = out[L.O_NSTEPS] * prm[L.P_H]
    if task == TASK_GOAL:
        rs[M_N1] = rs[R_SUCCESS]
        rs[M_N3] = rs[R_NAV]
    elif task == TASK_PATH:
        rs[M_N1] = rs[R_XINT] / duration if duration > 0.0 else abs(rs[R_NAV])
        rs[M_N2] = abs(rs[R_NAV])
    ground = int(prm[L.P_MEDIUM]) == L.MEDIUM_GROUND
    rs[M_AVG] = distance / duration if duration > 0.0 else 0.0
    rs[M_DIST] = distance
    rs[M_DISP] = math.hypot(dx, dy)
    rs[M_DUR] = duration
    rs[M_COT] = out[L.O_E_ACT] / (tp[T_MASS] * prm[L.P_G] * distance) if distance > 0.0 else math.inf
    rs[M_EMED] = out[L.O_E_FRICTION] if ground else out[L.O_E_FLUID]
    rs[M_EACT] = out[L.O_E_ACT]
    rs[M_WACT] = out[L.O_W_ACT]


@njit(cache=True, error_model="numpy", _nrt=False)
def robot_reset(sf, ibuf, tf, obs, n_act, n_path):
    """After the simulator's reset of the robot given by its blocks, as :func:`robot_step_blocks` takes them.

    The episode of its task starts here (centre of mass, zero powers and rewards, metrics,
    observation).
    """
    s, t = L.sim_views(sf, ibuf), task_views(tf, obs, ibuf.shape[1] // 2, n_act, n_path)
    rs = t.rs
    rs[:] = 0.0
    x, y = _com(s.q, t.w)
    rs[R_COMX] = rs[R_COM0X] = x
    rs[R_COMY] = rs[R_COM0Y] = y
    if int(t.tp[T_TASK]) != TASK_DIRECTION:
        _navigate(t.tp, rs, t.path, x, y, True)
        rs[R_S0] = rs[R_S]
        rs[M_N2] = math.inf  # time to goal: not reached yet
    _metrics(s.out, s.prm, t.tp, rs)
    rs[R_HEADING] = _observe(s, t, False)


@njit(cache=True, error_model="numpy", _nrt=False)
def robot_step(s, t):
    """One control step of one robot; returns the status.

    The robot is its simulator's arrays ``s`` (:class:`~soft_snake_gym.physics.SimArrays`) and its
    task's ``t`` (:class:`TaskArrays`, with the action in ``t.act``). The status is ``OK``, a
    failure code, or :data:`BAD_ACTION` if the action has a non-finite entry, in which case nothing
    changes.

    Clips ``act`` to [-1, 1] and turns it into rates (curvature rates for a swimmer, length
    rates for an inchworm) cut at the rest-shape bounds; advances ``tp[T_NSUB]`` integrator
    steps; on success updates the centre of mass, powers, observation and metrics. On a failure
    they keep their last valid values. The reward terms and the reward are written either way.
    """
    s, t = SimArrays(*s), TaskArrays(*t)
    sq = step_begin(s, t)
    if sq != sq:
        return BAD_ACTION
    before = energies_before(s)
    status = stepper.simulate(s, t.uk, t.ul, int(t.tp[T_NSUB]))
    step_end(s, t, status, sq, before, False)
    return status


@njit(cache=True, inline="always", error_model="numpy")
def step_begin(s, t):
    """The start of :func:`robot_step`: the action clipped and scaled to the rates in ``t.uk``/``t.ul``.

    Returns the squared norm of the clipped action, NaN if the action has a non-finite entry.
    """
    kbar, lbar, prm = s.kbar, s.lbar, s.prm
    act, tp, uk, ul = t.act, t.tp, t.uk, t.ul
    dt = tp[T_DT]
    if int(tp[T_KIND]) == SWIM:
        return observe.scale_rates(act, tp[T_SCALE], kbar, tp[T_LO], tp[T_HI], dt, uk)
    # with the actuators' lag tau the rest length coasts on: lbar + tau lbar_dot moves at exactly
    # the commanded rate, so bounding it (not lbar) keeps lbar itself within the limits
    lrate = s.buf[L.B_LRATE]
    for k in range(lbar.size):
        ul[k] = lbar[k] + prm[L.P_LAG] * lrate[k]
    return observe.scale_rates(act, tp[T_SCALE], ul, tp[T_LO], tp[T_HI], dt, ul)


@njit(cache=True, inline="always", error_model="numpy")
def energies_before(s):
    """The energy totals :func:`step_end` needs from before the physics: actuator, its work, the medium's."""
    out = s.out
    ground = int(s.prm[L.P_MEDIUM]) == L.MEDIUM_GROUND
    return out[L.O_E_ACT], out[L.O_W_ACT], out[L.O_E_FRICTION] if ground else out[L.O_E_FLUID]


@njit(cache=True, inline="always", error_model="numpy")
def step_end(s, t, status, sq, before, curved):
    """The end of :func:`robot_step`, after the physics ended with ``status``.

    The centre of mass, powers, observation and metrics (on success), the reward terms and the
    reward (always). ``curved``: a swimmer's curvatures and rates are already in ``t.raw``.
    """
    q, prm, out = s.q, s.prm, s.out
    tp, rs, w = t.tp, t.rs, t.w
    dt = tp[T_DT]
    ground = int(prm[L.P_MEDIUM]) == L.MEDIUM_GROUND
    e_act0, w_act0, e_med0 = before
    nsub = int(tp[T_NSUB])
    rs[R_STATUS] = status
    rs[R_ASQ] = sq
    task = int(tp[T_TASK])
    xte = 0.0
    bonus = 0.0
    if status == L.OK:
        x, y = _com(q, w)
        if task == TASK_DIRECTION:
            fwd = ((x - rs[R_COMX]) * tp[T_GCOS] + (y - rs[R_COMY]) * tp[T_GSIN]) / dt
        else:  # progress toward the target or along the path
            s_old = rs[R_S]
            _navigate(tp, rs, t.path, x, y, False)
            fwd = (rs[R_S] - s_old) / dt
            if task == TASK_GOAL:
                if rs[R_SUCCESS] == 0.0 and rs[R_NAV] <= tp[T_RADIUS]:
                    rs[R_SUCCESS] = 1.0
                    bonus = tp[T_BONUS]
                    rs[M_N2] = out[L.O_NSTEPS] * prm[L.P_H]
            else:
                xte = abs(rs[R_NAV])
                rs[R_XINT] += xte * dt
                rs[R_SUCCESS] = 1.0 if xte <= tp[T_RADIUS] else 0.0
        d_med = (out[L.O_E_FRICTION] if ground else out[L.O_E_FLUID]) - e_med0
        if int(tp[T_ESRC]) == ENERGY_MEDIUM:
            epow = d_med / dt
        else:
            epow = (out[L.O_E_ACT] - e_act0) / dt
        if nsub == 1:  # the simulator's own figures for its one step
            rs[R_P_ACT] = out[L.O_P_ACT]
            rs[R_P_MED] = out[L.O_P_FRICTION] if ground else out[L.O_P_FLUID]
        else:  # averages over the control step
            rs[R_P_ACT] = (out[L.O_W_ACT] - w_act0) / dt
            rs[R_P_MED] = d_med / dt
        rs[R_COMX] = x
        rs[R_COMY] = y
        rs[R_HEADING] = _observe(s, t, curved)
        _metrics(out, prm, tp, rs)
    else:
        fwd = 0.0
        epow = 0.0
    rs[R_FWD] = fwd
    rs[R_EPOW] = epow
    rs[R_RF] = tp[T_WF] * fwd
    rs[R_RE] = -tp[T_WE] * epow
    rs[R_RC] = -tp[T_WC] * sq
    rs[R_RFAIL] = -tp[T_FAIL] if status != L.OK else 0.0
    rs[R_RXTE] = -tp[T_WXTE] * xte
    rs[R_RSUCC] = bonus
    rs[R_REWARD] = rs[R_RF] + rs[R_RE] + rs[R_RC] + rs[R_RFAIL] + rs[R_RXTE] + rs[R_RSUCC]


@njit(cache=True, error_model="numpy", _nrt=False)
def robot_step_blocks(sf, ibuf, tf, obs, n_act, n_path):
    """:func:`robot_step` of one robot given by its blocks: what the single env calls.

    The simulator's block ``sf`` and ``ibuf`` (``SimArrays.f``, ``.ibuf``), the task's ``tf`` and
    ``obs`` (``TaskArrays.f``, ``.obs``), the action's and the path's sizes: four arrays for numba
    to unbox instead of twenty (about 1 µs instead of 4 per call).
    """
    return robot_step(L.sim_views(sf, ibuf), task_views(tf, obs, ibuf.shape[1] // 2, n_act, n_path))


@njit(cache=True, inline="always")
def _borrowed_stacks(s, t):
    """The batch's stacked arrays (the plain tuples the batched kernels take), each ``layout.borrowed``.

    A view of one robot's rows then pays no reference counting: :func:`_robot` took 330 ns a
    call on counted stacks, not inlined, and 67 ns inlined on borrowed ones.
    """
    return L.borrowed_arrays(s), L.borrowed(TaskArrays(*t))


@njit(cache=True, inline="always", error_model="numpy")
def _robot(s, t, i):
    """Robot ``i``'s views of stacked simulator and task arrays (over its rows of the blocks)."""
    N = s.ibuf.shape[-1] // 2
    return (
        L.sim_views(s.f[i], s.ibuf[i]),
        task_views(t.f[i], t.obs[i], N, t.act.shape[-1], t.path.shape[-2]),
    )


@njit(cache=True, parallel=True, error_model="numpy")
def batch_step(active, s, t, status, threads):
    """:func:`robot_step` for every active robot, spread over ``threads`` of numba's threads.

    For every robot ``i`` with ``active[i]``, of stacked simulator arrays ``s`` and task arrays
    ``t`` (leading robot axis); robot ``i``'s status into ``status[i]``. The robots go in blocks
    of ``lanes.LANES`` (:func:`block_step`), the rest one by one; each thread takes one run of
    them (as ``prange`` would, :func:`step_units`).
    """
    count = units(status.size)
    parts = max(1, min(threads, count))
    for c in prange(parts):
        step_units(active, s, t, status, c * count // parts, (c + 1) * count // parts)


@njit(cache=True, error_model="numpy")
def batch_step_serial(active, s, t, status):
    """:func:`batch_step` on the calling thread alone (no thread-pool launch: for one thread)."""
    step_units(active, s, t, status, 0, units(status.size))


@njit(cache=True, error_model="numpy")
def step_units(active, s, t, status, first, end):
    """Units ``first`` .. ``end - 1`` of :func:`units` on one thread, in its own :func:`_block_scratch`.

    ``s``, ``t``: the plain tuples :func:`batch_step` takes, borrowed here (:func:`_borrowed_stacks`;
    numba's parallel pass does not take borrowed arrays).
    """
    s, t = _borrowed_stacks(s, t)
    active, status = L.borrowed((active, status))
    owned = _block_scratch(s.q.shape[1])
    scratch = L.borrowed(owned)
    lo, hi = first_robot(first, status.size), first_robot(end, status.size)
    if _crawls(active, s, lo, hi):
        _crawl(active, s, t, status, lo, hi, scratch)
        return owned
    for u in range(first, end):
        _step_unit(active, s, t, status, u, scratch)
    return owned  # used after the loop, so that numba frees it only then: its borrowed views are not counted


CRAWL_MIN = 4 * lanes.LANES
"""The fewest active crawlers on a thread that :func:`_crawl` takes: its lanes pay from about 64
(docs/performance_history.md, "Worms in lanes"); with fewer, the lanes idle while the last robots finish."""


@njit(cache=True, error_model="numpy", _nrt=False)
def _crawls(active, s, lo, hi):
    """True if robots ``lo`` .. ``hi - 1`` go to :func:`_crawl`: at least ``CRAWL_MIN`` active ones, ``lanes.crawl_eligible``."""
    count = 0
    for i in range(lo, hi):
        if active[i]:
            if not lanes.crawl_eligible(s.prm[i]):
                return False
            count += 1
    return count >= CRAWL_MIN


@njit(cache=True, error_model="numpy")
def _crawl(active, s, t, status, lo, hi, scratch):
    """:func:`robot_step` for the active robots ``lo`` .. ``hi - 1``, the crawlers' physics sixteen at a time.

    Each robot's task start (:func:`step_begin`), then the physics of all (``lanes.crawl``: each
    robot's ``stepper.simulate`` bit for bit), then each task end (:func:`step_end`): the robots
    are independent, so each ends as :func:`robot_step` leaves it. Every active robot is
    ``lanes.crawl_eligible`` (:func:`_crawls`); one with another ``h`` or sub-step count than the
    first steps one by one.
    """
    x, p = scratch[0], scratch[1]
    m = hi - lo
    robots, nsteps, code = np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m, np.int64)
    sq, before = np.empty(m), np.empty((3, m))
    count = 0
    for i in range(lo, hi):
        if not active[i]:
            continue
        si, ti = _robot(s, t, i)
        if count > 0 and (
            si.prm[L.P_H] != s.prm[robots[0], L.P_H] or si.prm[L.P_SUBSTEPS] != s.prm[robots[0], L.P_SUBSTEPS]
        ):
            status[i] = robot_step(si, ti)
            continue
        sq[count] = step_begin(si, ti)
        if sq[count] != sq[count]:
            status[i] = BAD_ACTION
            continue
        before[0, count], before[1, count], before[2, count] = energies_before(si)
        robots[count], nsteps[count] = i, int(ti.tp[T_NSUB])
        count += 1
    if count == 0:
        return
    wi, wf = np.empty((lanes.N_WORK_INT, lanes.LANES), np.int64), np.empty((lanes.N_WORK, lanes.LANES))
    lanes.crawl(s, t.uk, t.ul, robots[:count], nsteps[:count], code, x, p, wi, wf)
    for k in range(count):
        i = robots[k]
        si, ti = _robot(s, t, i)
        step_end(si, ti, code[k], sq[k], (before[0, k], before[1, k], before[2, k]), False)
        status[i] = code[k]


TAIL_MIN = 6
"""The fewest robots past the last full block that go as a block of their own, the rest of its lanes
idle: from 6 robots such a block costs less than the robots one by one (docs/performance_history.md,
"The tail block")."""


@njit(cache=True, inline="always")
def _blocks(n):
    """The blocks of ``n`` robots: the full blocks of ``lanes.LANES``, and the tail block if ``TAIL_MIN`` or more are left."""
    return n // lanes.LANES + (1 if n % lanes.LANES >= TAIL_MIN else 0)


@njit(cache=True, inline="always")
def units(n):
    """The units of work of ``n`` robots: the :func:`_blocks`, then each robot left over."""
    blocks = _blocks(n)
    return blocks + max(0, n - blocks * lanes.LANES)


@njit(cache=True, inline="always")
def first_robot(u, n):
    """The first robot of unit ``u`` of :func:`units` (``n`` for ``u`` past the last)."""
    blocks = _blocks(n)
    return min(u * lanes.LANES, n) if u <= blocks else blocks * lanes.LANES + u - blocks


@njit(cache=True, error_model="numpy")
def _block_scratch(n2):
    """The arrays :func:`block_step` works in, for robots of ``n2 = 2N`` unknowns: one set per thread.

    The block's flat arrays (``lanes.allocate``), its parameters, Newton's results, and per lane:
    the squared action, the energies before the step, the status, the iterations and sums of a
    sub-step, ``simulate``'s sums over the sub-steps, and the stage's and the sub-step's flags.
    """
    n = lanes.LANES
    z = np.zeros
    return (lanes.allocate(n2), z((lanes.N_LANE_PRM, n)), z((5, n)), z(n), z((3, n)), z(n, dtype=np.int64),
            z(n, dtype=np.int64), z((5, n)), z(n, dtype=np.int64), z(n), z((4, n)), z(n, dtype=np.bool_),
            z(n, dtype=np.bool_), z(n))  # fmt: skip


@njit(cache=True, inline="always", error_model="numpy")
def _step_unit(active, s, t, status, u, scratch):
    """Unit ``u`` of :func:`units`: a block (:func:`_step_block`) or one robot past the last block.

    Inlined into :func:`step_units`, as :func:`_step_block` is: called, they cost about 0.7 µs
    a block before any robot stepped (16 calls of :func:`_step_block` 11.5 µs, the same choice
    written inline 0.7 µs: docs/performance_history.md, "Blocks copy only what a step reads; the
    block's choice inlined"), and 256 eels stepped 1.05 times slower.
    """
    blocks = _blocks(status.size)
    if u < blocks:
        _step_block(active, s, t, status, u * lanes.LANES, scratch)
        return
    i = blocks * lanes.LANES + (u - blocks)
    if active[i]:
        si, ti = _robot(s, t, i)
        status[i] = robot_step(si, ti)


@njit(cache=True, inline="always", error_model="numpy")
def _step_block(active, s, t, status, first, scratch):
    """Robots ``first`` .. ``first + LANES - 1`` (fewer in the tail block).

    By :func:`block_step` if it takes them all, else one by one.
    """
    count = min(lanes.LANES, status.size - first)
    together = active[first : first + count].any()  # a robot to step, and all eligible alike
    for r in range(count):
        i = first + r
        together &= block_eligible(s.prm[i], t.tp[i])
        together &= (
            s.prm[i, L.P_H] == s.prm[first, L.P_H]
            and s.prm[i, L.P_SUBSTEPS] == s.prm[first, L.P_SUBSTEPS]
            and s.prm[i, L.P_METHOD] == s.prm[first, L.P_METHOD]
        )
    if together:
        block_step(active, s, t, first, status, scratch)
        return
    for r in range(count):
        i = first + r
        if active[i]:
            si, ti = _robot(s, t, i)
            status[i] = robot_step(si, ti)


@njit(cache=True, error_model="numpy", _nrt=False)
def block_eligible(prm, tp):
    """True if :func:`block_step` takes the robot: a swimmer on SDIRK2 or BDF2, one step of ``h`` per action.

    A swimmer's inputs are curvature rates (its rest lengths never move), in water with the
    consistent added mass (``lanes.eligible``).
    """
    return (
        lanes.eligible(prm)
        and (int(prm[L.P_METHOD]) == L.METHOD_SDIRK2 or int(prm[L.P_METHOD]) == L.METHOD_BDF2)
        and int(tp[T_NSUB]) == 1
        and int(tp[T_KIND]) == SWIM
    )


@njit(cache=True, error_model="numpy", _nrt=False)
def block_step(active, s, t, first, status, scratch):
    """:func:`robot_step` for the ``active`` robots of the ``LANES`` from ``first``, each stage at once.

    Every robot must be :func:`block_eligible`, with the same ``h``, sub-steps and method;
    ``scratch`` is :func:`_block_scratch`'s. It is :func:`robot_step` with ``stepper.simulate``'s
    step of SDIRK2 or BDF2 sub-steps written out: each robot's task start and end and the step's
    end are the same functions, the stages run in the block (``lanes.stage_start`` or
    ``lanes.bdf2_start``, ``lanes.newton``, ``lanes.stage_end``) in the scalar kernels' order of
    operations, and the sums are ``simulate``'s, so every robot ends bit for bit as
    :func:`robot_step` leaves it (all but ``buf``'s ``lanes.STAGE_ROWS``, the stages' work, which
    no step reads before it writes them). A robot whose step fails is put back whole at once
    (``lanes.put``); the others' state after their last stage (``lanes.put_state``). Under BDF2 a
    robot without a history (a fresh state, which ``simulate`` starts with an SDIRK2 step) takes
    its step alone, by :func:`robot_step`, and its lane idles. An inactive robot's
    lane idles: the block computes it as it does a lane whose action is bad, and puts nothing of
    it back (:func:`batch_step` leaves that robot alone). So do the lanes past the last robot in
    the tail block, where ``lanes.take`` copies the last robot in again.
    """
    n_lanes = lanes.LANES
    x, p, result, sq, before, state, iters, acc, niter, resid, energy, go, ran, act0 = scratch
    state[:] = L.OK  # each robot's status in the step
    niter[:] = 0  # simulate's sums over the sub-steps
    resid[:] = 0.0
    energy[:] = 0.0
    bdf2 = int(s.prm[first, L.P_METHOD]) == L.METHOD_BDF2
    count = min(n_lanes, status.size - first)
    for r in range(n_lanes):
        if r >= count or not active[first + r]:
            state[r] = _IDLE
            continue
        si, ti = _robot(s, t, first + r)
        if bdf2 and math.isnan(si.buf[L.B_QPREV, 0]):
            status[first + r] = robot_step(si, ti)
            state[r] = _IDLE
            continue
        sq[r] = step_begin(si, ti)
        if sq[r] != sq[r]:
            state[r] = BAD_ACTION
            continue
        before[0, r], before[1, r], before[2, r] = energies_before(si)
        if si.prm[L.P_LAG] == 0.0:  # stepper.simulate's start of a step
            L.copy_into(si.buf[L.B_LRATE, : si.lbar.size], ti.ul)
        si.out[L.O_NJAC] = si.out[L.O_NRES] = si.out[L.O_NFACTOR] = 0.0
    lanes.take(s, t.uk, first, x, p)
    if bdf2:
        lanes.take_history(s, first, x)
    nsub = int(s.prm[first, L.P_SUBSTEPS])
    dt = s.prm[first, L.P_H] / nsub  # as stepper.simulate
    for _ in range(nsub):
        for r in range(n_lanes):
            ran[r] = go[r] = state[r] == L.OK
            iters[r] = 0
            acc[:, r] = 0.0  # a sub-step's residual, fluid, damping and friction energy, actuator work
        if bdf2 and go.any():  # stepper._bdf2_substep and implicit_energies
            lanes.bdf2_start(x, p, dt)
            for r in range(n_lanes):
                act0[r] = x.power[0, r]
            lanes.newton(s, first, go, x, p, 2.0 * dt / 3.0, result)
            lanes.stage_end(x, p, 1)
            for r in range(n_lanes):
                if go[r]:
                    state[r], iters[r], acc[0, r] = int(result[0, r]), int(result[1, r]), result[2, r]
                    p_damp = x.power[1, r] if stepper.is_damped(s.prm[first + r]) else 0.0
                    acc[1, r], acc[2, r], acc[3, r], acc[4, r] = stepper.implicit_sums(
                        dt, act0[r], x.power[0, r], p_damp, result[3, r], result[4, r]
                    )
                    if state[r] != L.OK:
                        lanes.put(s, first + r, x, r, x.v)
                        lanes.put_history(s, first + r, x, r)
        for stage in range(0 if bdf2 else 2):  # stepper._sdirk2_substep
            for r in range(n_lanes):
                go[r] = state[r] == L.OK
            if not go.any():
                break
            lanes.stage_start(x, p, stage, dt)
            lanes.newton(s, first, go, x, p, stepper.GAMMA * dt, result)
            lanes.stage_end(x, p, stage)
            for r in range(n_lanes):
                if go[r]:
                    damped = stepper.is_damped(s.prm[first + r])
                    newton = (int(result[0, r]), int(result[1, r]), result[2, r], result[3, r], result[4, r])
                    sums = (iters[r], acc[0, r], acc[1, r], acc[2, r], acc[3, r], acc[4, r])
                    state[r], (iters[r], acc[0, r], acc[1, r], acc[2, r], acc[3, r], acc[4, r]) = (
                        stepper.sdirk2_stage_sums(
                            stage, dt, damped, newton, x.power[0, r], x.power[1, r], sums
                        )
                    )
                    if state[r] != L.OK:
                        lanes.put(s, first + r, x, r, x.v)
        for r in range(n_lanes):  # simulate's sums of the sub-step
            if ran[r]:
                niter[r] = max(niter[r], iters[r])
                resid[r] = max(resid[r], acc[0, r])
                for k in range(4):
                    energy[k, r] += acc[k + 1, r]
    lanes.energies(x, p)
    for r in range(n_lanes):
        i = first + r
        if state[r] == _IDLE:
            continue
        if state[r] == BAD_ACTION:
            status[i] = BAD_ACTION
            continue
        si, ti = _robot(s, t, i)
        together = state[r] == L.OK  # else put back earlier: the block moved on
        if together:
            lanes.put_state(s, i, x, r, x.v)
            if bdf2:
                lanes.put_history(s, i, x, r)
        st = stepper.end_step(
            si, state[r], niter[r], resid[r], energy[0, r], energy[1, r], energy[2, r], energy[3, r]
        )
        out, e = si.out, x.energy
        if together:  # the block's energies are this robot's
            out[L.O_E_KIN], out[L.O_E_ELASTIC], out[L.O_T_FLUID] = e[0, r], e[1, r], e[2, r]
            stepper.ledger(out)
        else:
            stepper.ledger_energies(si)
        curved = together and st == L.OK  # and its curvatures and rates, for the observation
        if curved:
            lanes.curvatures_into(x, r, ti.raw)
        step_end(si, ti, st, sq[r], (before[0, r], before[1, r], before[2, r]), curved)
        status[i] = st
