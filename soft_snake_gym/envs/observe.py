"""Physics to observation and inputs: small numba kernels on one robot's simulator arrays.

They take the simulator's flat interleaved positions ``q`` and velocities ``v`` (2N,), its
rest shape and integer scratch, and write into preallocated outputs. The environments call
them through the per-robot step of :mod:`soft_snake_gym.envs.task`, one robot at a time in
``SoftEel-v0``/``SoftWorm-v0`` and over all robots at once in the batched vector env, so both
compute observations with the same code.
"""

from __future__ import annotations

import math

from numba import njit

from soft_snake_gym.physics import geometry, layout
from soft_snake_gym.physics.cache import drop_stale_cache
from soft_snake_gym.physics.layout import STUCK

__all__ = ["scale_rates", "body_velocity", "swim_observation", "inch_observation"]

drop_stale_cache(__file__, [geometry.__file__, layout.__file__])  # the cached kernels embed their code


@njit(cache=True, _nrt=False)
def scale_rates(action, scale, value, lo, hi, dt, out):
    """Physical rates from a normalized action.

    Clips ``action`` to [-1, 1] in place, then writes ``out = scale * action``, each rate cut
    so that ``value + dt * out`` stays in ``[lo, hi]`` (a rate that would cross a bound lands
    on it; at the bound an outward rate is zero). ``action``, ``value``, ``out``: (n,) float64;
    ``out`` may be ``value``.

    Returns:
        The squared norm of the clipped action, or NaN if an entry of ``action`` is not finite
        (``out`` is then meaningless).
    """
    sq = 0.0
    for i in range(out.size):
        a = action[i]
        if not math.isfinite(a):
            return math.nan
        a = min(max(a, -1.0), 1.0)
        action[i] = a
        sq += a * a
        r = scale * a
        up = (hi - value[i]) / dt
        down = (lo - value[i]) / dt
        if r > up:
            r = up
        if r < down:
            r = down
        out[i] = r
    return sq


@njit(cache=True, _nrt=False)
def body_velocity(q, v, w):
    """Heading of the tail-to-head chord [rad] and the centre-of-mass velocity along it and to its left.

    The velocities are in [m/s]; ``w`` (N,) are the mass fractions.
    """
    n = w.size
    vx = 0.0
    vy = 0.0
    for i in range(n):
        vx += w[i] * v[2 * i]
        vy += w[i] * v[2 * i + 1]
    heading = math.atan2(q[2 * n - 1] - q[1], q[2 * n - 2] - q[0])
    c, s = math.cos(heading), math.sin(heading)
    return heading, c * vx + s * vy, c * vy - s * vx


@njit(cache=True, _nrt=False)
def _clip_into(raw, low, high, out):
    for i in range(raw.size):
        x = raw[i]
        if x > high[i]:
            x = high[i]
        elif x < low[i]:
            x = low[i]
        out[i] = x


@njit(cache=True, error_model="numpy", _nrt=False)
def swim_observation(q, v, kbar, w, goal, low, high, raw, out, geo):
    """The ``SoftEel-v0`` observation.

    Kappa (N-2), kappa_dot (N-2), kbar (N-2), com_velocity_body (2), goal_direction_body (2: cos,
    sin of ``goal`` minus the heading).

    Writes the unclipped values (float64) into ``raw`` and, clipped to ``[low, high]``, into
    ``out`` (float32); ``geo`` is the edge geometry of ``q`` (``geometry.edge_geometry``, which
    a step leaves in ``buf[B_GEO]``). Returns the heading [rad].
    """
    n = kbar.size
    geometry.curvatures_and_rates_at(geo, v, raw[:n], raw[n : 2 * n])
    return swim_observation_curved(q, v, kbar, w, goal, low, high, raw, out)


@njit(cache=True, error_model="numpy", _nrt=False)
def swim_observation_curved(q, v, kbar, w, goal, low, high, raw, out):
    """:func:`swim_observation` with the curvatures and their rates already in ``raw[:2 (N-2)]``.

    The batched env's blocks of eels compute those for sixteen eels at once (``lanes.stage_end``).
    """
    n = kbar.size
    for j in range(n):
        raw[2 * n + j] = kbar[j]
    heading, along, lateral = body_velocity(q, v, w)
    raw[3 * n] = along
    raw[3 * n + 1] = lateral
    raw[3 * n + 2] = math.cos(goal - heading)
    raw[3 * n + 3] = math.sin(goal - heading)
    _clip_into(raw, low, high, out)
    return heading


@njit(cache=True, error_model="numpy", _nrt=False)
def inch_observation(q, v, lbar, friction, ground, w, low, high, raw, out, geo):
    """The ``SoftWorm-v0`` observation.

    Edge_lengths (N-1), edge_length_rates (N-1), lbar (N-1), stuck (N, 0/1 from the friction states
    ``friction``; all 0 unless ``ground``), com_velocity_body (2). Same outputs as
    :func:`swim_observation` (``geo`` the edge geometry of ``q``); returns the heading [rad].
    """
    m = lbar.size
    for k in range(m):
        raw[k] = geo[0, 2 * k]
        tx, ty = geo[1, 2 * k], geo[1, 2 * k + 1]
        raw[m + k] = tx * (v[2 * k + 2] - v[2 * k]) + ty * (v[2 * k + 3] - v[2 * k + 1])
        raw[2 * m + k] = lbar[k]
    for i in range(m + 1):
        raw[3 * m + i] = 1.0 if ground and friction[i] == STUCK else 0.0
    heading, along, lateral = body_velocity(q, v, w)
    raw[4 * m + 1] = along
    raw[4 * m + 2] = lateral
    _clip_into(raw, low, high, out)
    return heading
