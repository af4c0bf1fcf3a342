"""Physics to observation and inputs: small numba kernels on simulator arrays.

They take the simulator's flat interleaved positions ``q`` and velocities ``v`` (2N,), its
rest shape and the quantities its properties return, and write into preallocated outputs, so
one call replaces a dozen small numpy operations per step (the env's overhead on top of
``Simulator.step``), and a batched environment can call them robot by robot. They call no
other compiled function, so their on-disk cache cannot go stale when the physics kernels
change.
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["scale_rates", "body_velocity", "swim_observation", "inch_observation"]


@njit(cache=True)
def scale_rates(action, scale, value, lo, hi, dt, out):
    """Physical rates from a normalized action.

    Clips ``action`` to [-1, 1] in place, then writes ``out = scale * action``, each rate cut
    so that ``value + dt * out`` stays in ``[lo, hi]`` (a rate that would cross a bound lands
    on it; at the bound an outward rate is zero). ``action``, ``value``, ``out``: (n,) float64.

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


@njit(cache=True)
def body_velocity(q, v, w):
    """Heading of the tail-to-head chord [rad] and the centre-of-mass velocity along it and to
    its left [m/s]; ``w`` (N,) are the mass fractions."""
    n = w.size
    vx = 0.0
    vy = 0.0
    for i in range(n):
        vx += w[i] * v[2 * i]
        vy += w[i] * v[2 * i + 1]
    heading = math.atan2(q[2 * n - 1] - q[1], q[2 * n - 2] - q[0])
    c, s = math.cos(heading), math.sin(heading)
    return heading, c * vx + s * vy, c * vy - s * vx


@njit(cache=True)
def _clip_into(raw, low, high, out):
    for i in range(raw.size):
        x = raw[i]
        if x > high[i]:
            x = high[i]
        elif x < low[i]:
            x = low[i]
        out[i] = x


@njit(cache=True)
def swim_observation(kappa, kappa_dot, kbar, q, v, w, goal, low, high, raw, out):
    """The ``SoftEel-v0`` observation: kappa (N-2), kappa_dot (N-2), kbar (N-2),
    com_velocity_body (2), goal_direction_body (2: cos, sin of ``goal`` minus the heading).

    Writes the unclipped values (float64) into ``raw`` and, clipped to ``[low, high]``, into
    ``out`` (float32). Returns the heading [rad].
    """
    n = kbar.size
    for j in range(n):
        raw[j] = kappa[j]
        raw[n + j] = kappa_dot[j]
        raw[2 * n + j] = kbar[j]
    heading, along, lateral = body_velocity(q, v, w)
    raw[3 * n] = along
    raw[3 * n + 1] = lateral
    raw[3 * n + 2] = math.cos(goal - heading)
    raw[3 * n + 3] = math.sin(goal - heading)
    _clip_into(raw, low, high, out)
    return heading


@njit(cache=True)
def inch_observation(lengths, length_rates, lbar, stuck, q, v, w, low, high, raw, out):
    """The ``SoftWorm-v0`` observation: edge_lengths (N-1), edge_length_rates (N-1),
    lbar (N-1), stuck (N, 0/1), com_velocity_body (2). Same outputs as
    :func:`swim_observation`; returns the heading [rad]."""
    m = lbar.size
    for k in range(m):
        raw[k] = lengths[k]
        raw[m + k] = length_rates[k]
        raw[2 * m + k] = lbar[k]
    for i in range(m + 1):
        raw[3 * m + i] = 1.0 if stuck[i] else 0.0
    heading, along, lateral = body_velocity(q, v, w)
    raw[4 * m + 1] = along
    raw[4 * m + 2] = lateral
    _clip_into(raw, low, high, out)
    return heading
