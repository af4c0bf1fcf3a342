"""The thesis reproduction.

Every sweep, both trajectory figures, the sources' headline case, and
``docs/thesis_reproduction.md`` with the finding-by-finding table, computed from the CSVs.

Each finding the thesis states in words is turned into a count over the grid cells (how many
comparisons go the stated way), so the verdict is a number, not an impression: **yes** when at
least :data:`YES_FRACTION` of the comparisons agree, **partly** from :data:`PARTLY_FRACTION`,
**no** below.

The report is the template ``thesis_reproduction.md`` shipped beside this module
(:class:`string.Template`); every number in it is computed here, from the CSVs, the runs of
this module or the package's own parameters.
"""

from __future__ import annotations

import math
import os
import string
import time
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from soft_snake_gym.agents import make_policy
from soft_snake_gym.evaluation import evaluate, make_eval_env, summarize
from soft_snake_gym.gaits import serpenoid, serpenoid_phase
from soft_snake_gym.params import Rod
from soft_snake_gym.policies import parse_policy_spec, policy_gait
from soft_snake_gym.policies.decentralized import DecentralizedParams
from soft_snake_gym.policies.inching import PULSE_DUTY, InchingPIDParams
from soft_snake_gym.policies.open_loop import OpenLoopParams, SerpenoidParams
from soft_snake_gym.policies.pid import PIDParams
from soft_snake_gym.studies.figures import (
    COMPARISON_CENTRALIZED,
    SETTLED_AFTER,
    make_all_figures,
    mean_error_after,
    rest_start_options,
    rollout,
)
from soft_snake_gym.studies.sweep import (
    ALPHA_MAX_FRACTION,
    SOFT_E_BEND,
    SOFT_GAINS,
    STUDIES,
    StudyGrid,
    cell_key,
    control_step,
    read_results,
    run_cell,
    run_sweep,
)

__all__ = [
    "findings",
    "headline_case",
    "headline_table",
    "headline_window",
    "model_departures",
    "write_report",
    "reproduce",
]

YES_FRACTION = 0.8
"""A finding holds (**yes**) when at least this fraction of its comparisons agree."""

PARTLY_FRACTION = 0.5
"""A finding holds **partly** from this fraction."""

LEVEL = 5e-3
"""Two neighbouring cells differ when they differ by more than this fraction of the larger."""

CONVERGED_SUBSTEPS = 16
"""Integration steps per control step where a closed loop's result must not come from the step."""

TEMPLATE = Path(__file__).with_name("thesis_reproduction.md")
"""The report's template (:class:`string.Template`)."""


# --- formatting --------------------------------------------------------------------------------
def _sci(x: float) -> str:
    """``1.87e4``, ``1.875e6``: a modulus as the sources write it."""
    mantissa, exponent = f"{x:.6e}".split("e")
    return f"{mantissa.rstrip('0').rstrip('.')}e{int(exponent)}"


def _gains(p: Any) -> str:
    """``(Kp, Kd, Ki)`` of a mapping or parameter object, as ``(10, 2, 1)``."""
    get = p.get if isinstance(p, dict) else lambda k: getattr(p, k)
    return f"({get('Kp'):g}, {get('Kd'):g}, {get('Ki'):g})"


def _pi_text(x: float, sep: str = "/") -> str:
    """A rational multiple of pi in words: ``2 pi/3``, ``2 pi``, ``pi / 9`` with ``sep=" / "``."""
    f = Fraction(x / math.pi).limit_denominator(64)
    num = "pi" if f.numerator == 1 else f"{f.numerator} pi"
    return num if f.denominator == 1 else f"{num}{sep}{f.denominator}"


def _count(n: int) -> str:
    """A small count in words (``three``), a large one in digits."""
    words = ("zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine")
    return words[n] if 0 <= n < len(words) else str(n)


# --- findings ------------------------------------------------------------------------------------
def _ok(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in rows if not r.get("failure") and np.isfinite(r.get("average_speed", math.nan))]


def _table(rows, x, y, z, **where):
    """{(x, y): z} of the rows matching ``where``."""
    return {(r[x], r[y]): r[z] for r in rows if all(r[k] == v for k, v in where.items())}


def _verdict(agree: int, total: int) -> str:
    if total == 0:
        return "n/a"
    f = agree / total
    return "yes" if f >= YES_FRACTION else "partly" if f >= PARTLY_FRACTION else "no"


def _pairs_increasing(table: dict, along: int, with_ties: bool = False):
    """Count neighbouring pairs along axis ``along`` (0.

    First key, 1: second) where z rises (by more than :data:`LEVEL` of the larger value); with
    ``with_ties`` also those that stay level.
    """
    keys = sorted(table)
    others = sorted({k[1 - along] for k in keys})
    agree = total = ties = 0
    for o in others:
        line = sorted((k[along], table[k]) for k in keys if k[1 - along] == o)
        for (_, a), (_, b) in zip(line, line[1:], strict=False):
            total += 1
            tol = LEVEL * max(abs(a), abs(b))
            agree += b > a + tol
            ties += abs(b - a) <= tol
    return (agree, ties, total) if with_ties else (agree, total)


def _more(a: dict, b: dict, keys: list) -> int:
    """How many of ``keys`` have ``a[k] > b[k]``."""
    return sum(a[k] > b[k] for k in keys)


def _finding(finding: str, agree: int, total: int, numbers: str) -> dict[str, str]:
    return {"finding": finding, "verdict": _verdict(agree, total), "numbers": numbers}


def _speed_rises_with_frequency(ol: dict, pid: dict) -> list[dict[str, str]]:
    a1, t1 = _pairs_increasing(ol, 1)
    a1p, t1p = _pairs_increasing(pid, 1)
    alphas = sorted({k[0] for k in ol})
    mid = alphas[len(alphas) // 2] if alphas else math.nan
    line = sorted((k[1], v) for k, v in ol.items() if k[0] == mid)
    ex = (
        f"; at alpha = {mid:.2f} rad open loop goes {line[0][1]:.4f} m/s at omega = {line[0][0]:.2f} and {line[-1][1]:.4f} m/s at {line[-1][0]:.2f} rad/s"
        if line
        else ""
    )
    return [
        _finding(
            f"Speed rises with frequency (swimming, E_bend = {_sci(SOFT_E_BEND)} Pa)",
            a1 + a1p,
            t1 + t1p,
            f"speed rises in {a1}/{t1} neighbouring frequency steps open loop, {a1p}/{t1p} with PID{ex}",
        )
    ]


def _speed_peaks_inside(ol: dict) -> list[dict[str, str]]:
    inner = total = 0
    peaks = []
    for w in sorted({k[1] for k in ol}):
        line = sorted((k[0], v) for k, v in ol.items() if k[1] == w)
        if len(line) < 3:
            continue
        total += 1
        i = int(np.argmax([v for _, v in line]))
        inner += 0 < i < len(line) - 1
        peaks.append(f"{w:.2f}: {line[i][0]:.2f}")
    return [
        _finding(
            "At fixed frequency, speed peaks at an intermediate amplitude (open loop)",
            inner,
            total,
            f"interior peak at {inner}/{total} frequencies; peak amplitude by omega [rad/s]: alpha [rad] = "
            + ", ".join(peaks)
            + " (cells that self-intersect are excluded)",
        )
    ]


def _power_rises(pw: dict) -> list[dict[str, str]]:
    aa, ta = _pairs_increasing(pw, 0)
    aw, tw = _pairs_increasing(pw, 1)
    lo = min(pw.items(), key=lambda kv: kv[1]) if pw else None
    hi = max(pw.items(), key=lambda kv: kv[1]) if pw else None
    rng = (
        f"; from {lo[1]:.3g} W (alpha {lo[0][0]:.2f}, omega {lo[0][1]:.2f}) to {hi[1]:.3g} W (alpha {hi[0][0]:.2f}, omega {hi[0][1]:.2f})"
        if pw
        else ""
    )
    return [
        _finding(
            "Fluid power rises with amplitude and with frequency (open loop)",
            aa + aw,
            ta + tw,
            f"rises in {aa}/{ta} amplitude steps and {aw}/{tw} frequency steps{rng}",
        )
    ]


def _stiffer_is_faster(stiff: list[dict]) -> list[dict[str, str]]:
    s = _ok(stiff)
    es = sorted({r["E_bend"] for r in s})
    agree = total = 0
    for a in sorted({r["alpha"] for r in s}):
        for w in sorted({r["omega"] for r in s}):
            v = [
                next(
                    (r["average_speed"] for r in s if (r["alpha"], r["omega"], r["E_bend"]) == (a, w, e)),
                    None,
                )
                for e in es
            ]
            for x, y in zip(v, v[1:], strict=False):
                if x is not None and y is not None:
                    total += 1
                    agree += y > x
    means = []
    for e in es:
        common = [r["average_speed"] for r in s if r["E_bend"] == e]
        means.append(f"{e:.3g} Pa: median {np.median(common):.4f} m/s" if common else f"{e:.3g} Pa: -")
    return [
        _finding(
            "Stiffer bodies swim faster open loop",
            agree,
            total,
            f"speed rises with E_bend in {agree}/{total} stiffness steps at equal gait; " + "; ".join(means),
        )
    ]


def _feedback_in_water(g: list[dict], ol: dict, pid: dict, p_ol: dict) -> list[dict[str, str]]:
    """Feedback beats open loop on speed and error at low stiffness, at a higher energy cost."""
    err_ol = _table(g, "alpha", "omega", "curvature_error", controller="open-loop")
    err_pid = _table(g, "alpha", "omega", "curvature_error", controller="pid")
    p_pid = _table(g, "alpha", "omega", "mean_fluid_power", controller="pid")
    e_ol = _table(g, "alpha", "omega", "energy_actuator", controller="open-loop")
    e_pid = _table(g, "alpha", "omega", "energy_actuator", controller="pid")
    both = sorted(set(ol) & set(pid))
    faster = _more(pid, ol, both)
    lower_err = _more(err_ol, err_pid, both)
    costlier = _more(p_pid, p_ol, both)
    act_costlier = _more(e_pid, e_ol, both)
    ratio = np.median([pid[k] / ol[k] for k in both if ol[k] > 0]) if both else math.nan
    eratio = np.median([err_pid[k] / err_ol[k] for k in both]) if both else math.nan
    n = len(both)
    return [
        _finding(
            "Feedback (PID) swims faster than open loop at low stiffness",
            faster,
            n,
            f"PID faster in {faster}/{n} cells, median speed ratio PID/open loop {ratio:.2f}",
        ),
        _finding(
            "Feedback has a lower curvature error than open loop at low stiffness",
            lower_err,
            n,
            f"PID error lower in {lower_err}/{n} cells, median error ratio PID/open loop {eratio:.2f}",
        ),
        _finding(
            "Feedback costs more energy",
            costlier,
            n,
            f"PID fluid power higher in {costlier}/{n} cells, actuator energy higher in {act_costlier}/{n}",
        ),
    ]


def _friction(c: list[dict]) -> list[dict[str, str]]:
    """On land, more static and less kinetic friction go further."""
    agree_s = total_s = agree_d = total_d = ties_s = ties_d = 0
    for ctrl in ("inching", "inching-pid"):
        d = _table(c, "mu_s", "mu_d", "distance", controller=ctrl)
        a, ti, t = _pairs_increasing(d, 0, with_ties=True)  # along mu_s at fixed mu_d
        agree_s, ties_s, total_s = agree_s + a, ties_s + ti, total_s + t
        a, ti, t = _pairs_increasing(d, 1, with_ties=True)  # along mu_d at fixed mu_s: should fall
        agree_d, ties_d, total_d = agree_d + (t - a - ti), ties_d + ti, total_d + t
    d_ol = _table(c, "mu_s", "mu_d", "distance", controller="inching")
    best = max(d_ol.items(), key=lambda kv: kv[1]) if d_ol else None
    worst = min(d_ol.items(), key=lambda kv: kv[1]) if d_ol else None
    span = (
        (
            f"; open loop from {worst[1]:.3f} m (mu_s {worst[0][0]:.2f}, mu_d {worst[0][1]:.2f}) to {best[1]:.3f} m "
            f"(mu_s {best[0][0]:.2f}, mu_d {best[0][1]:.2f})"
        )
        if d_ol
        else ""
    )
    return [
        _finding(
            "On land, more static friction goes further",
            agree_s,
            total_s,
            f"distance rises with mu_s in {agree_s}/{total_s} steps at fixed mu_d, "
            f"stays level (within {100 * LEVEL:g} %) in {ties_s}{span}",
        ),
        _finding(
            "On land, less kinetic friction goes further",
            agree_d,
            total_d,
            f"distance falls with mu_d in {agree_d}/{total_d} steps at fixed mu_s, stays level in {ties_d}",
        ),
    ]


def _feedback_on_land(c: list[dict]) -> list[dict[str, str]]:
    """Feedback goes further on land at a higher energy cost."""
    d_ol = _table(c, "mu_s", "mu_d", "distance", controller="inching")
    d_cl = _table(c, "mu_s", "mu_d", "distance", controller="inching-pid")
    f_ol = _table(c, "mu_s", "mu_d", "energy_friction", controller="inching")
    f_cl = _table(c, "mu_s", "mu_d", "energy_friction", controller="inching-pid")
    both = sorted(set(d_ol) & set(d_cl))
    further = _more(d_cl, d_ol, both)
    dearer = _more(f_cl, f_ol, both)
    tot_ol = sum(d_ol[k] for k in both)
    tot_cl = sum(d_cl[k] for k in both)
    return [
        _finding(
            "On land, feedback goes further",
            further,
            len(both),
            f"closed loop further in {further}/{len(both)} cells; summed distance {tot_cl:.3f} m vs {tot_ol:.3f} m open loop",
        ),
        _finding(
            "On land, feedback costs more energy",
            dearer,
            len(both),
            f"closed-loop friction energy higher in {dearer}/{len(both)} cells",
        ),
    ]


def findings(gait: list[dict], stiff: list[dict], inch: list[dict]) -> list[dict[str, str]]:
    """The thesis's findings with our verdicts and numbers, from the rows of the three studies."""
    g = _ok(gait)
    ol = _table(g, "alpha", "omega", "average_speed", controller="open-loop")
    pid = _table(g, "alpha", "omega", "average_speed", controller="pid")
    power = _table(g, "alpha", "omega", "mean_fluid_power", controller="open-loop")
    land = [r for r in inch if not r.get("failure")]
    return [
        *_speed_rises_with_frequency(ol, pid),
        *_speed_peaks_inside(ol),
        *_power_rises(power),
        *_stiffer_is_faster(stiff),
        *_feedback_in_water(g, ol, pid, power),
        *_friction(land),
        *_feedback_on_land(land),
    ]


def _land_numbers(inch: list[dict[str, Any]]) -> dict[str, Any]:
    """The open-loop distance along the lowest-mu_d row and the highest-mu_s column."""
    ol = [r for r in inch if r["controller"] == "inching" and not r.get("failure")]
    if not ol:
        nan = math.nan
        return {
            "energy_low": "no data",
            "mu_d_low": nan,
            "row_low": "-",
            "mu_s_list": "-",
            "mu_s_high": nan,
            "col_high": "-",
            "mu_d_list": "-",
        }
    md_lo = min(r["mu_d"] for r in ol)
    ms_hi = max(r["mu_s"] for r in ol)
    row = sorted((r["mu_s"], r["distance"], r["energy_friction"]) for r in ol if r["mu_d"] == md_lo)
    col = sorted((r["mu_d"], r["distance"]) for r in ol if r["mu_s"] == ms_hi)
    energies = [e for _, _, e in row]
    return {
        "energy_low": (
            f"{min(energies):.1f} J"
            if f"{min(energies):.1f}" == f"{max(energies):.1f}"
            else f"{min(energies):.1f}-{max(energies):.1f} J"
        )
        + f" at mu_d = {md_lo:.2f} for every mu_s",
        "mu_d_low": md_lo,
        "row_low": ", ".join(f"{d:.3f}" for _, d, _ in row),
        "mu_s_list": ", ".join(f"{m:.2f}" for m, _, _ in row),
        "mu_s_high": ms_hi,
        "col_high": ", ".join(f"{d:.3f}" for _, d in col),
        "mu_d_list": ", ".join(f"{m:.2f}" for m, _ in col),
    }


#: The sources' headline case (issue 9, item 6): the thesis gait's frequency, two amplitudes, the
#: actual-curvature PID with gains (Kp, Kd, Ki) = :data:`HEADLINE_GAINS` and the open loop, for
#: each physics model.
HEADLINE_OMEGA = 2 * math.pi / 3
HEADLINE_ALPHAS = (math.pi / 6, math.pi / 3)
HEADLINE_GAINS = {"Kp": 10, "Kd": 1, "Ki": 5}
HEADLINE_CONTROLLERS = {
    f"PID {_gains(HEADLINE_GAINS)}": ("pid", HEADLINE_GAINS),
    "open loop": ("open-loop", {}),
}
HEADLINE_MODELS = {"default": None, "thesis preset": "thesis"}


def headline_window(transient_cycles: float = 2, cycles: float = 2) -> str:
    """In words, the window :func:`headline_case` averages over."""
    period = 2 * math.pi / HEADLINE_OMEGA
    start, end = transient_cycles * period, (transient_cycles + cycles) * period
    return f"{cycles:g} gait periods, {start:.3g}-{end:.3g} s, after {transient_cycles:g} periods of start-up transient"


def headline_case(
    transient_cycles: float = 2,
    cycles: float = 2,
    models: tuple[str, ...] | None = None,
    alphas: tuple[float, ...] = HEADLINE_ALPHAS,
) -> list[dict[str, Any]]:
    """The sources' headline case on ``SoftEel-v0``.

    Each controller of :data:`HEADLINE_CONTROLLERS` at omega = 2 pi/3 rad/s and each amplitude,
    starting at rest on its gait (``start_on_gait``, no start noise), for each physics model of
    :data:`HEADLINE_MODELS` (the package defaults and the ``thesis`` preset).

    Args:
        transient_cycles: gait periods left out as the start-up transient.
        cycles: gait periods the steady-state metrics are averaged over.
        models: keys of :data:`HEADLINE_MODELS` (default: all).
        alphas: gait amplitudes [rad].

    Returns:
        One row per (model, controller, alpha): ``model``, ``controller``, ``alpha`` [rad],
        ``omega`` [rad/s], ``speed_cm_s`` (steady-state speed: the centre of mass's displacement
        over the window, whatever its direction, per time [cm/s]),
        ``fluid_power`` [W] and ``curvature_error`` [-] (means over the steady-state window),
        ``failure`` ("" if none).
    """
    if transient_cycles < 0 or cycles <= 0:
        raise ValueError(f"transient_cycles = {transient_cycles!r} must be >= 0 and cycles = {cycles!r} > 0")
    models = tuple(HEADLINE_MODELS) if models is None else models
    unknown = [m for m in models if m not in HEADLINE_MODELS]
    if unknown:
        raise ValueError(f"models {unknown} are unknown; choose from {list(HEADLINE_MODELS)}")
    period = 2 * math.pi / HEADLINE_OMEGA
    rows = []
    for model in models:
        for alpha in alphas:
            for controller, (name, options) in HEADLINE_CONTROLLERS.items():
                gait = {**options, "alpha": alpha, "omega": HEADLINE_OMEGA}
                spec = f"{name}:" + ",".join(f"{k}={v!r}" for k, v in gait.items())
                env_kwargs: dict[str, Any] = {"start_on_gait": policy_gait(spec)}
                if HEADLINE_MODELS[model] is not None:
                    env_kwargs["preset"] = HEADLINE_MODELS[model]
                dt = control_step("SoftEel-v0", env_kwargs)
                env_kwargs["max_episode_steps"] = int(round((transient_cycles + cycles) * period / dt))
                env = make_eval_env("SoftEel-v0", seed=0, env_kwargs=env_kwargs)
                ep = evaluate(make_policy(spec, env), env, episodes=1, transient=transient_cycles * period)[0]
                env.close()
                rows.append(
                    {
                        "model": model,
                        "controller": controller,
                        "alpha": alpha,
                        "omega": HEADLINE_OMEGA,
                        "speed_cm_s": 100.0 * ep["com_speed"],
                        "fluid_power": ep["window_fluid_power"],
                        "curvature_error": ep["curvature_error"],
                        "failure": ep["failure"],
                    }
                )
    return rows


def headline_table(rows: list[dict[str, Any]]) -> str:
    """The rows of :func:`headline_case` as a Markdown table."""
    lines = [
        "| model | controller | alpha [rad] | speed [cm/s] | fluid power [W] | curvature error [-] |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        tail = f" (failed: {r['failure']})" if r["failure"] else ""
        lines.append(
            f"| {r['model']} | {r['controller']} | {r['alpha']:.4f} (pi/{math.pi / r['alpha']:.3g}) | "
            f"{r['speed_cm_s']:.2f}{tail} | {r['fluid_power']:.3f} | {r['curvature_error']:.4f} |"
        )
    return "\n".join(lines)


def model_departures(grid: StudyGrid) -> dict[str, float]:
    """The numbers of the report's sections that the sweeps do not give, each from a short run.

    The sections are "where the model departs" and "trajectories".

    Returns:
        ``soft_error_open_loop``, ``soft_error_pid``: mean curvature error [-] of each at the
        thesis gait at ``E_bend`` = :data:`SOFT_E_BEND` (one swim-gait cell each);
        ``stiff_error_open_loop``, ``stiff_error_pid``: mean curvature error [-] at the default
        stiffness, as ``soft-snake evaluate SoftEel-v0 --policy open-loop`` / ``pid`` reports it
        (3 episodes, seeds 0-2, 2 s transient);
        ``sine_distance``: distance [m] of the sinusoidal inching wave in ``grid.inch_duration``
        on the default ground;
        ``unsettled_error``, ``unsettled_error_default_step``: mean curvature error [-] after
        :data:`SETTLED_AFTER` s of the decentralized PID with the gains :class:`PIDParams`
        defaults to, from rest on the gait, with the integration step divided by
        :data:`CONVERGED_SUBSTEPS` and at the default step (whose numerical damping hides the
        instability).
    """
    gait = SerpenoidParams()
    soft = {
        c: run_cell(
            {
                "study": "swim-gait",
                "controller": c,
                "alpha": gait.alpha,
                "omega": gait.omega,
                "E_bend": SOFT_E_BEND,
            },
            grid,
        )["curvature_error"]
        for c in ("open-loop", "pid")
    }
    stiff = {}
    for spec in ("open-loop", "pid"):
        env = make_eval_env("SoftEel-v0", seed=0)
        stiff[spec] = summarize(evaluate(make_policy(spec, env), env, episodes=3, transient=2.0))[
            "curvature_error"
        ][0]
        env.close()
    kwargs = {"reset_noise_scale": 0.0}
    kwargs["max_episode_steps"] = int(round(grid.inch_duration / control_step("SoftWorm-v0", kwargs)))
    env = make_eval_env("SoftWorm-v0", seed=0, env_kwargs=kwargs)
    sine = evaluate(make_policy("inching:wave=sine", env), env, episodes=1, transient=0.0)[0]["distance"]
    env.close()
    gains = ",".join(f"{k}={getattr(PIDParams(), k)!r}" for k in ("Kp", "Kd", "Ki"))
    spec = f"decentralized:{gains},startup=0"  # the chain from the first step, as the sources run it
    chain = {
        substeps: rollout(
            "SoftEel-v0",
            spec,
            6.0,
            env_kwargs={"reset_noise_scale": 0.0, "integrator": {"substeps": substeps}},
            reset_options=rest_start_options(),
        )
        for substeps in (1, CONVERGED_SUBSTEPS)
    }
    return {
        "soft_error_open_loop": soft["open-loop"],
        "soft_error_pid": soft["pid"],
        "stiff_error_open_loop": stiff["open-loop"],
        "stiff_error_pid": stiff["pid"],
        "sine_distance": sine,
        "unsettled_error": mean_error_after(chain[CONVERGED_SUBSTEPS]),
        "unsettled_error_default_step": mean_error_after(chain[1]),
    }


def _kappa_des_amplitude(samples: int = 360) -> float:
    """The largest desired curvature [-] of the thesis gait over one period (N = Rod().N)."""
    p = SerpenoidParams()
    n = Rod().N - 2
    delta = p.delta if p.delta is not None else 2 * math.pi / n  # SerpenoidParams' default
    period = 2 * math.pi / p.omega
    return max(
        float(np.abs(serpenoid(serpenoid_phase(t, n, p.omega, delta), p.omega, p.alpha)[0]).max())
        for t in np.linspace(0.0, period, samples, endpoint=False)
    )


def _parameters(grid: StudyGrid) -> dict[str, str]:
    """The report's numbers that are the package's own parameters."""
    rod = Rod()
    soft = Rod(E_bend=SOFT_E_BEND)
    inch = InchingPIDParams()
    centralized = PIDParams(**parse_policy_spec(COMPARISON_CENTRALIZED)[1])
    return {
        "yes_percent": f"{100 * YES_FRACTION:g}",
        "partly_percent": f"{100 * PARTLY_FRACTION:g}",
        "headline_gains": _gains(HEADLINE_GAINS),
        "headline_omega": _pi_text(HEADLINE_OMEGA),
        "default_E": _sci(rod.E),
        "soft_E_bend": _sci(SOFT_E_BEND),
        "soft_EI_per_node": f"{soft.EI / soft.edge_length:.2f}",  # lvor = l for an interior node
        "kappa_des_amplitude": f"{_kappa_des_amplitude():.2f}",
        "saturation": f"{PIDParams().saturation:g}",
        "pulse_duty": f"{PULSE_DUTY:g}",
        "inch_duration": f"{grid.inch_duration:g}",
        "pid_gains": _gains(PIDParams()),
        "decentralized_gains": _gains(DecentralizedParams()),
        "comparison_gains": (
            _gains(centralized)
            if _gains(centralized) == _gains(DecentralizedParams())
            else f"{_gains(centralized)} and {_gains(DecentralizedParams())}"
        ),
        "n_nodes": f"{rod.N}",
        "transient_cycles": f"{grid.transient_cycles}",
        "cycles": f"{grid.cycles}",
        "soft_gains": _gains(SOFT_GAINS),
        "rest_gain": f"{OpenLoopParams().rest_gain:g}",
        "inch_eps": f"{inch.eps:g}",
        "inch_omega": _pi_text(inch.omega),
        "inch_delta_l": _pi_text(
            inch.delta_l if inch.delta_l is not None else 2 * math.pi / (rod.N - 1), " / "
        ),
        "inch_Kp": f"{inch.Kp:g}",
        "settled_after": f"{SETTLED_AFTER:g}",
    }


def _figures(rel: Path, grid: StudyGrid) -> dict[str, str]:
    """The figure blocks, captions with the grid's own numbers."""

    def fig(name: str, caption: str) -> str:
        return f"![{caption}]({rel.as_posix()}/{name})\n\n*{caption}*\n"

    t = f"{grid.inch_duration:g}"
    return {
        "fig_gait_speed": fig(
            "swim-gait_average_speed.png",
            f"Average speed, open loop (left) and PID {_gains(SOFT_GAINS)} (right)",
        ),
        "fig_gait_error": fig("swim-gait_curvature_error.png", "Mean curvature error |kappa_des - kappa|"),
        "fig_gait_power": fig("swim-gait_mean_fluid_power.png", "Mean power lost to the fluid"),
        "fig_stiff_speed": fig(
            "swim-stiffness_average_speed.png",
            f"Open-loop average speed at {_count(len(grid.e_bend))} bending moduli",
        ),
        "fig_stiff_power": fig(
            "swim-stiffness_mean_fluid_power.png",
            f"Open-loop fluid power at {_count(len(grid.e_bend))} bending moduli",
        ),
        "fig_inch_distance": fig(
            "inch-friction_distance.png", f"Distance in {t} s, open loop (left) and closed loop (right)"
        ),
        "fig_inch_energy": fig("inch-friction_energy_friction.png", f"Energy lost to friction in {t} s"),
        "fig_inch_length": fig("inch-friction_length_error.png", "Mean edge-length error |lbar_des - |e||"),
        "fig_snapshots": fig(
            "swim_snapshots.png",
            "Swimming snapshots over one gait cycle (PID, thesis gait, "
            "default stiffness), coloured by time, with head, tail and centre-of-mass traces",
        ),
        "fig_comparison": fig(
            "centralized_vs_decentralized.png",
            "Centralized vs decentralized PID from rest with curvature equal to the desired one",
        ),
    }


def write_report(path: Path, img: Path, facts: list[dict[str, str]], extras: dict[str, Any]) -> Path:
    """Write the Markdown report from :data:`TEMPLATE` (figures are linked relative to it).

    Args:
        path: the report.
        img: the folder of the figures and CSVs.
        facts: :func:`findings`.
        extras: what the run computed: ``grid`` (the text), ``sweeps`` (study -> cells, cpu,
            computed, seconds), ``comparison_errors``, and optionally ``grid_params`` (the
            :class:`StudyGrid`), ``workers``, ``headline`` with ``headline_window`` and
            ``headline_seconds``, ``land`` (:func:`_land_numbers`), ``inch_distance`` (the
            median inching distance [m]) and ``departures`` (:func:`model_departures`); what is
            missing reads "n/a".
    """
    grid = extras.get("grid_params") or StudyGrid()
    land = extras.get("land") or _land_numbers([])
    rel = img.relative_to(path.parent) if img.is_relative_to(path.parent) else img
    headline = extras.get("headline")
    cmp_ = extras["comparison_errors"]
    dep = extras.get("departures") or {}

    def number(value: float | None, fmt: str) -> str:
        return "n/a" if value is None or not math.isfinite(value) else format(value, fmt)

    values = {
        **_parameters(grid),
        **_figures(rel, grid),
        "grid": extras["grid"],
        "headline": headline_table(headline) if headline else "(not computed in this run)",
        "headline_window": extras.get("headline_window", "the steady state"),
        "headline_seconds": number(extras.get("headline_seconds"), ".0f"),
        "findings": "\n".join(f"| {f['finding']} | **{f['verdict']}** | {f['numbers']} |" for f in facts),
        "soft_error_open_loop": number(dep.get("soft_error_open_loop"), ".2f"),
        "soft_error_pid": number(dep.get("soft_error_pid"), ".2f"),
        "stiff_error_open_loop": number(dep.get("stiff_error_open_loop"), ".4f"),
        "stiff_error_pid": number(dep.get("stiff_error_pid"), ".4f"),
        "pulse_distance": number(extras.get("inch_distance"), ".1f"),
        "energy_low": land["energy_low"],
        "mu_d_low": f"{land['mu_d_low']:.2f}",
        "row_low": land["row_low"],
        "mu_s_list": land["mu_s_list"],
        "mu_s_high": f"{land['mu_s_high']:.2f}",
        "col_high": land["col_high"],
        "mu_d_list": land["mu_d_list"],
        "sine_distance_mm": number(1000 * dep["sine_distance"] if "sine_distance" in dep else None, ".0f"),
        "cores": f"{os.cpu_count() or 1}",
        "workers": (
            f"{extras['workers']} worker process{'es' if extras['workers'] != 1 else ''}"
            if "workers" in extras
            else "n/a worker processes"
        ),
        "timings": "\n".join(
            f"| {k} | {v['cells']} | {v['cpu']:.0f} | {v['computed']} | {v['seconds']:.0f} |"
            for k, v in extras["sweeps"].items()
        ),
        "error_centralized": f"{cmp_['centralized']:.4f}",
        "error_decentralized": f"{cmp_['decentralized']:.4f}",
        "unsettled_error": number(dep.get("unsettled_error"), ".3f"),
        "unsettled_error_default_step": number(dep.get("unsettled_error_default_step"), ".3f"),
        "converged_substeps": f"{CONVERGED_SUBSTEPS}",
    }
    path.write_text(string.Template(TEMPLATE.read_text()).substitute(values))
    return path


def reproduce(out: str | Path = "docs", workers: int | None = None, progress: bool = True, grid=None) -> Path:
    """Run everything and write ``<out>/thesis_reproduction.md``."""
    out = Path(out)
    img = out / "img"
    grid = grid or StudyGrid()
    sweeps, rows = {}, {}
    for name in STUDIES:
        t0 = time.perf_counter()
        res = run_sweep(name, img, grid, workers=workers, progress=progress)
        cells = STUDIES[name].cells(grid)
        results = read_results(res["csv"])
        rows[name] = [results[cell_key(c)] for c in cells if cell_key(c) in results]
        sweeps[name] = {
            "cells": len(cells),
            "computed": res["computed"],
            "seconds": time.perf_counter() - t0,
            "cpu": sum(r.get("wall_time", 0.0) for r in rows[name]),
        }
    extras = make_all_figures(img)
    extras["sweeps"] = sweeps
    extras["grid_params"] = grid
    extras["workers"] = max(1, workers or os.cpu_count() or 1)
    t0 = time.perf_counter()
    extras["headline"] = headline_case()
    extras["headline_seconds"] = time.perf_counter() - t0
    extras["headline_window"] = headline_window()
    extras["grid"] = (
        f"alpha {grid.n_alpha} values up to {ALPHA_MAX_FRACTION:g} x the self-intersection limit, omega {grid.n_omega} "
        f"values in [{grid.omega_min}, {grid.omega_max:.3f}] rad/s, E_bend {list(grid.e_bend)} Pa, "
        f"mu {grid.n_mu} values in [{grid.mu_s_min}, {grid.mu_s_max}] with mu_d <= mu_s"
    )
    facts = findings(rows["swim-gait"], rows["swim-stiffness"], rows["inch-friction"])
    extras["land"] = _land_numbers(rows["inch-friction"])
    distances = [r["distance"] for r in rows["inch-friction"] if not r.get("failure")]
    extras["inch_distance"] = float(np.median(distances)) if distances else None
    extras["departures"] = model_departures(grid)
    return write_report(out / "thesis_reproduction.md", img, facts, extras)
