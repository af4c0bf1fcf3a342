"""Steps per second, side by side with MuJoCo's ``Swimmer-v5`` (the library of ``soft-snake benchmark``).

Everything is measured in one run on one machine, so the ratios hold even when the absolute
numbers move with the load:

(a) ``gym.make("SoftEel-v0")`` and ``gym.make("SoftWorm-v0")``, one env each with Gymnasium's
    standard wrappers;
(b) the batched vector env (``gym.make_vec``) at 1, 16, 256 and 1024 robots, with one thread
    and, from 128 robots (where the env's default uses them), with every core;
(c) ``gym.make("Swimmer-v5")`` and a ``SyncVectorEnv`` of it (needs ``mujoco``), and EnvPool's
    ``Swimmer-v4`` (a C++ thread pool), one env and 256 envs on as many threads as the batched
    env's (needs ``envpool``); both come with the ``bench`` extra, and without them those rows
    are skipped and said so;
(d) PPO training throughput with the batched env, as three figures (environment steps per
    second of raw stepping with random actions, of stepping plus the policy's inference, and
    of the full ``model.learn``), and ``model.learn`` with SB3's ``SubprocVecEnv`` at equal
    ``n_envs`` (the package's ``SoftEel-v0`` PPO hyperparameters, ``VecNormalize``), the two
    models' rounds interleaved as the throughput cases' are;
(e) cost per robot step of the batched env against the number of nodes N = 10, 20, 50, 100
    (the same 1.62 m, 7.2 kg body cut into N - 1 edges, swimming the thesis's serpenoid gait);
(f) the machine's attainable peak, numpy's float64 matrix product (the BLAS's dgemm) on one
    thread and on every core, measured in each round, and the floating-point work of our rows
    against it: steps/s times the flops of a robot step counted from the kernels
    (:data:`FLOPS_PER_STEP`), as a fraction of the peak on the row's threads.

Throughput cases drive every env with uniform random actions in [-1, 1] (an untrained
policy), resetting when an episode ends; two extra rows drive 256 batched eels with the
thesis gait (a smooth policy: fewer Newton iterations per step) and with the optional BDF2
integrator (``integrator.method="bdf2"``, one implicit stage per step). Every row gives robot-steps
per second and simulated seconds per wall-clock second (steps/s times the env's control step,
read from the env: 0.01 s for ours, 0.04 s for the Swimmers). The cases are interleaved over ``repeats`` rounds
and each reports the median round, so a load change during the run hits all of them alike.
Results go to a JSON file and a PNG figure.
"""

from __future__ import annotations

import math
import os
import platform
import re
import statistics
import time
from collections.abc import Callable
from typing import Any
from xml.etree import ElementTree

import gymnasium as gym
import numba
import numpy as np
from threadpoolctl import threadpool_limits

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.envs.registration import importable_id
from soft_snake_gym.envs.vector import ROBOTS_PER_THREAD
from soft_snake_gym.gaits import serpenoid, serpenoid_phase
from soft_snake_gym.training import load_train_config, policy_kwargs, stopped_by, torch_for_learning

__all__ = ["run_benchmark", "format_report", "DEFAULT_ROBOTS", "DEFAULT_NODES", "ENVPOOL_ROBOTS"]

DEFAULT_ROBOTS = (1, 16, 256, 1024)
DEFAULT_NODES = (10, 20, 50, 100)
TARGETS = {
    "single_vs_swimmer": 3.0,
    "worm_single_vs_swimmer": 3.0,
    "batched256_vs_swimmer": 10.0,
    "batched256_vs_envpool": 3.0,
    "worm256_vs_swimmer": 10.0,
    "worm256_vs_envpool": 3.0,
    "ppo_batched_vs_subproc": 2.0,
}
"""The acceptance ratios: single envs in steps/s, 256 robots in simulated s per wall s."""
STRETCH = 30.0
"""Stretch goal of 256 eels against Swimmer-v5's single env, simulated s per wall s."""
ENVPOOL_ROBOTS = 256
FLOPS_PER_STEP = {"SoftEel-v0": 27_600, "SoftWorm-v0": 27_500}
"""Floating-point operations of a robot step under random actions, counted from the kernels for
the default bodies (docs/performance.md, "Floating-point work per robot step"): estimates, not
measurements; the variants' rows (the gait, BDF2) do other work and are left out."""
WARMUP_SECONDS = 0.5
"""Each case steps this long before the rounds, unmeasured: its first steps load numba's code (in
a fresh clone, compile it), and its first autoresets take paths its construction did not."""
MATMUL_SIZE = 1000
"""The side of the matrices whose product measures the peak: about 2 GFLOP a product."""
_PLAIN_ROW = re.compile(r"^(SoftEel-v0|SoftWorm-v0) (gym\.make|batched n=\d+ threads=(\d+))$")


# --- throughput cases ------------------------------------------------------------------------
class _SingleCase:
    """A ``gym.make`` env stepped by pre-drawn random actions, reset at episode ends."""

    def __init__(self, env_id: str, **kwargs: Any) -> None:
        self.env = gym.make(env_id, **kwargs)
        self.env.reset(seed=0)
        rng = np.random.default_rng(0)
        self.actions = rng.uniform(-1, 1, (1000,) + self.env.action_space.shape).astype(np.float32)
        self.next = 0  # the next action: the rounds go on through all of them, 100 at a time
        self.robots = 1
        self.dt = float(self.env.unwrapped.dt)

    def run(self, seconds: float) -> float:
        env, steps = self.env, 0
        start = time.perf_counter()
        while True:
            for a in self.actions[self.next : self.next + 100]:
                _, _, term, trunc, _ = env.step(a)
                if term or trunc:
                    env.reset()
            self.next = (self.next + 100) % len(self.actions)
            steps += 100
            elapsed = time.perf_counter() - start
            if elapsed >= seconds:
                return steps / elapsed


class _VectorCase:
    """A vector env (batched or ``SyncVectorEnv``) with autoreset; rate in robot-steps/s."""

    reset_seed: int | None = 0

    def __init__(self, make: Callable[[], Any], robots: int, actions: np.ndarray | None = None) -> None:
        self.env = make()
        self.dt = self._dt()
        self.env.reset(seed=self.reset_seed)
        rng = np.random.default_rng(0)
        if actions is None:
            actions = rng.uniform(-1, 1, (32,) + self.env.action_space.shape).astype(np.float32)
        self.actions = actions
        self.robots = robots
        for a in self.actions[:2]:  # load the compiled code
            self.env.step(a)

    def _dt(self) -> float:
        """The env's control step [s]: the batched env's own, or a ``SyncVectorEnv``'s first env's."""
        env = self.env
        return float(env.dt if hasattr(env, "dt") else env.envs[0].unwrapped.dt)

    def run(self, seconds: float) -> float:
        env, steps = self.env, 0
        start = time.perf_counter()
        while True:
            for a in self.actions:
                env.step(a)
            steps += len(self.actions)
            elapsed = time.perf_counter() - start
            if elapsed >= seconds:
                return steps * self.robots / elapsed


class _EnvPoolCase(_VectorCase):
    """EnvPool's ``Swimmer-v4`` with ``robots`` envs on ``threads`` threads (it autoresets itself)."""

    reset_seed = None  # EnvPool takes its seed at creation

    def __init__(self, robots: int, threads: int) -> None:
        import envpool  # here: optional (the bench extra), and only this case needs it

        rng = np.random.default_rng(0)
        super().__init__(
            lambda: envpool.make(
                "Swimmer-v4",
                env_type="gymnasium",
                num_envs=robots,
                batch_size=robots,
                num_threads=threads,
                seed=0,
            ),
            robots,
            rng.uniform(-1, 1, (32, robots, 2)),  # its action_space is one env's, (2,)
        )

    def _dt(self) -> float:
        """EnvPool's control step [s]: its ``frame_skip`` times the ``timestep`` of its model file."""
        cfg = self.env.spec.config
        path = os.path.join(cfg.base_path, "mujoco", "assets_gym", cfg.xml_file)
        return cfg.frame_skip * float(ElementTree.parse(path).getroot().find("option").get("timestep"))


def _gait_actions(robots: int, n: int = 8, steps: int = 300) -> np.ndarray:
    """The thesis serpenoid as normalized SoftEel-v0 actions, (steps, robots, n) float32.

    The serpenoid has alpha = pi/6, omega = 2 pi/3; the actions are those of ``robots`` eels of
    ``n + 2`` nodes.
    """
    alpha, omega = (math.pi / 6) * 8 / n, 2 * math.pi / 3  # the same body shape at any n
    t = (np.arange(steps) + 0.5) * 0.01
    rates = np.array([serpenoid(serpenoid_phase(ti, n, omega, 2 * math.pi / n), omega, alpha)[1] for ti in t])
    return np.repeat((rates / (2 * math.pi))[:, None, :], robots, axis=1).astype(np.float32)


def _kernel_share(case: _VectorCase, seconds: float) -> float:
    """Fraction of a batched env's step time spent in the compiled call (the rest: Python, autoresets, infos)."""
    venv = case.env
    venv.kernel_seconds = 0.0
    start = time.perf_counter()
    case.run(seconds)
    return venv.kernel_seconds / (time.perf_counter() - start)


def matmul_rate(threads: int, seconds: float, n: int = MATMUL_SIZE) -> float:
    """GFLOP/s of numpy's float64 ``n`` x ``n`` matrix product on ``threads`` BLAS threads, the best of ``seconds``' products.

    The BLAS's dgemm keeps a core's vector units nearly full, so this is what the machine can
    reach, measured on it (its nominal peak needs its clock and its vector units, which a
    virtual machine need not report).
    """
    rng = np.random.default_rng(0)
    a, b, out = rng.random((n, n)), rng.random((n, n)), np.empty((n, n))
    best = 0.0
    with threadpool_limits(threads, user_api="blas"):
        np.matmul(a, b, out=out)  # the BLAS's threads started, its buffers allocated
        start = time.perf_counter()
        while True:
            t0 = time.perf_counter()
            np.matmul(a, b, out=out)
            now = time.perf_counter()
            best = max(best, 2.0 * n**3 / (now - t0))
            if now - start >= seconds:
                return best / 1e9


def _have_mujoco() -> str | None:
    try:
        import mujoco  # noqa: F401
    except ImportError as err:
        return f"mujoco is not installed ({err}); pip install 'soft-snake-gym[bench]' for the Swimmer-v5 rows"
    return None


def _have_envpool() -> str | None:
    try:
        import envpool  # noqa: F401
    except ImportError as err:
        return f"envpool is not installed ({err}); pip install 'soft-snake-gym[bench]' for the EnvPool rows"
    return None


# --- PPO --------------------------------------------------------------------------------------
def _ppo_settings(env_id: str) -> tuple[int, dict[str, Any], dict[str, Any]]:
    """n_envs, PPO keywords and env keywords of the package's PPO config for ``env_id``."""
    cfg = load_train_config(env_id)
    return cfg.n_envs, {**cfg.hyperparams, "policy_kwargs": policy_kwargs(cfg)}, dict(cfg.env_kwargs)


def ppo_model(kind: str, env_id: str, n_envs: int | None = None) -> Any:
    """A PPO model at the package's settings for ``env_id``, warmed up (one rollout and update).

    On the batched env (``kind="batched"``) or on ``SubprocVecEnv`` (``"subproc"``), either one
    wrapped in ``VecNormalize``, with ``n_envs`` envs (the config's without it), logging nowhere.
    The caller closes ``model.get_env()``.
    """
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    # here, not at the top: sb3 imports Stable-Baselines3 and torch (seconds), which the
    # command line would otherwise pay on every start
    from soft_snake_gym.sb3 import SoftVecEnv

    cfg_envs, ppo_kwargs, env_kwargs = _ppo_settings(env_id)
    n_envs = n_envs or cfg_envs
    if kind == "batched":
        venv = SoftVecEnv(env_id, n_envs=n_envs, seed=0, **env_kwargs)
    else:
        venv = make_vec_env(
            importable_id(env_id), n_envs=n_envs, seed=0, env_kwargs=env_kwargs, vec_env_cls=SubprocVecEnv
        )
    try:
        model = PPO("MlpPolicy", VecNormalize(venv), seed=0, device="cpu", **ppo_kwargs)
        # no log files: SB3's default logger would leave an empty /tmp/SB3-<date> per run
        model.set_logger(Logger(folder=None, output_formats=[]))
        model.learn(model.n_steps * n_envs)  # warm-up: workers started, kernels loaded, torch initialized
    except BaseException:
        venv.close()
        raise
    return model


def time_ppo(
    env_id: str,
    n_envs: int | None,
    timesteps: int,
    repeats: int,
    kinds: tuple[str, ...] = ("batched", "subproc"),
) -> list[dict[str, Any]]:
    """PPO's environment steps per second with the batched env and with ``SubprocVecEnv``.

    At the package's PPO settings for ``env_id``: one model per kind in ``kinds``, each after
    one warm-up rollout and update, then ``repeats`` interleaved rounds of about
    ``timesteps / repeats`` steps each (whole rollouts, at least one), so that a change of load
    hits both kinds alike; each figure is the median round. A round times the full
    ``model.learn`` and, for the batched env, first two parts of it (as Isaac Lab reports
    training throughput): raw stepping of the ``VecNormalize``-wrapped env with random actions,
    and stepping plus the policy's inference (its forward pass on each observation, as a
    rollout does); and the env's own step beneath ``VecNormalize``, the only part of the batched
    ``learn`` that is ours (:func:`_ratios` makes of it what PPO would make if it cost nothing).
    """
    import torch
    from stable_baselines3.common.utils import obs_as_tensor

    with torch_for_learning():  # as soft_snake_gym.training runs torch
        models: dict[str, Any] = {}
        try:
            for kind in kinds:
                models[kind] = ppo_model(kind, env_id, n_envs)
            n_envs = models[kinds[0]].n_envs
            rollout = models[kinds[0]].n_steps * n_envs
            per_round = rollout * max(1, round(timesteps / (repeats * rollout)))
            steps = per_round // n_envs
            actions = np.random.default_rng(0).uniform(
                -1, 1, (steps, n_envs) + models[kinds[0]].action_space.shape
            )
            rounds: dict[str, dict[str, list[float]]] = {kind: {} for kind in kinds}
            for _ in range(repeats):
                for kind, model in models.items():
                    rates = rounds[kind]
                    env = model.get_env()
                    if kind == "batched":
                        for name, stepped in (("env", env.venv), ("step", env)):
                            start = time.perf_counter()
                            for a in actions:
                                stepped.step(a)
                            rates.setdefault(name, []).append(per_round / (time.perf_counter() - start))
                        obs = env.reset()
                        low, high = env.action_space.low, env.action_space.high
                        start = time.perf_counter()
                        for _ in range(steps):
                            with torch.no_grad():
                                act = model.policy(obs_as_tensor(obs, model.device))[0].numpy()
                            obs = env.step(np.clip(act, low, high))[0]
                        rates.setdefault("inference", []).append(per_round / (time.perf_counter() - start))
                    start = time.perf_counter()
                    model.learn(per_round, reset_num_timesteps=False)
                    rates.setdefault("learn", []).append(per_round / (time.perf_counter() - start))
        finally:
            for model in models.values():
                model.get_env().close()
    rows = []
    for kind, rates in rounds.items():
        row = {
            "kind": kind,
            "n_envs": n_envs,
            "timesteps": per_round * repeats,
            "steps_per_s": statistics.median(rates["learn"]),
            "rounds": rates["learn"],
        }
        if "step" in rates:
            row["env_steps_per_s"] = statistics.median(rates["env"])
            row["step_steps_per_s"] = statistics.median(rates["step"])
            row["inference_steps_per_s"] = statistics.median(rates["inference"])
        rows.append(row | {k: getattr(models[kind], k) for k in ("n_steps", "batch_size", "n_epochs")})
    return rows


# --- cost against N -------------------------------------------------------------------------
def time_nodes(N: int, robots: int, seconds: float) -> dict[str, Any]:
    """Microseconds per robot step of the batched eel with N nodes (same body, one thread)."""
    rod = {"N": N, "edge_length": 1.62 / (N - 1), "edge_mass": 7.2 / (N - 1)}
    venv = gym.make_vec("SoftEel-v0", num_envs=robots, num_threads=1, rod=rod)
    venv.reset(seed=0)
    actions = _gait_actions(robots, N - 2, 300)
    for a in actions[:2]:
        venv.step(a)
    steps, iters = 0, 0.0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        for a in actions[2:]:
            _, _, _, _, info = venv.step(a)
            iters += float(np.mean(info["newton_iterations"]))
            steps += 1
    elapsed = time.perf_counter() - start
    us = elapsed / (steps * robots) * 1e6
    return {
        "N": N,
        "robots": robots,
        "us_per_robot_step": us,
        "us_per_node_step": us / N,
        "mean_newton_iterations": iters / steps,
    }


# --- the run ----------------------------------------------------------------------------------
def run_benchmark(
    seconds: float = 1.0,
    repeats: int = 3,
    robots: tuple[int, ...] = DEFAULT_ROBOTS,
    sync_robots: int = 16,
    ppo: bool = True,
    ppo_timesteps: int = 8192,
    ppo_n_envs: int | None = None,
    nodes: tuple[int, ...] = DEFAULT_NODES,
    node_robots: int = 64,
    envpool_robots: int = ENVPOOL_ROBOTS,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run every case; returns the results (see :func:`format_report`).

    The batched worms run at 256 robots (or, if 256 is not among ``robots``, at the largest count).
    Each case first steps unmeasured for ``min(seconds, WARMUP_SECONDS)``, then the cases run in
    ``repeats`` interleaved rounds of ``seconds`` each.
    A ``KeyboardInterrupt`` (Ctrl-C; SIGTERM under ``training.sigterm_as_interrupt``) ends the run
    early and keeps what it measured: in the rounds, the complete ones (every case in the same
    rounds, as the ratios need them), and after them, each row made before it; the results then
    say where in ``interrupted``. One in the warm-up or the first round, with no round complete,
    propagates.
    """
    say = progress or (lambda msg: None)
    all_threads = numba.config.NUMBA_NUM_THREADS
    cases: dict[str, Any] = {}
    say("building the environments")
    cases["SoftEel-v0 gym.make"] = _SingleCase("SoftEel-v0")
    cases["SoftWorm-v0 gym.make"] = _SingleCase("SoftWorm-v0")
    for n in robots:
        # all cores only where the env's default would use them (>= 2 x ROBOTS_PER_THREAD robots)
        for threads in sorted({1, all_threads if n >= 2 * ROBOTS_PER_THREAD else 1}):
            cases[f"SoftEel-v0 batched n={n} threads={threads}"] = _VectorCase(
                lambda n=n, threads=threads: gym.make_vec("SoftEel-v0", num_envs=n, num_threads=threads), n
            )
    n = 256 if 256 in robots else max(robots)
    for threads in sorted({1, all_threads if n >= 2 * ROBOTS_PER_THREAD else 1}):
        cases[f"SoftWorm-v0 batched n={n} threads={threads}"] = _VectorCase(
            lambda n=n, threads=threads: gym.make_vec("SoftWorm-v0", num_envs=n, num_threads=threads), n
        )
    if 256 in robots:  # a smooth policy: the thesis gait (fewer Newton iterations per step)
        cases["SoftEel-v0 batched n=256 threads=1, gait actions"] = _VectorCase(
            lambda: gym.make_vec("SoftEel-v0", num_envs=256, num_threads=1), 256, _gait_actions(256)
        )
        cases[f"SoftEel-v0 batched n=256 threads={all_threads}, bdf2"] = _VectorCase(
            lambda: gym.make_vec(
                "SoftEel-v0", num_envs=256, num_threads=all_threads, integrator={"method": "bdf2"}
            ),
            256,
        )
    mujoco_missing = _have_mujoco()
    if mujoco_missing is None:
        cases["Swimmer-v5 gym.make"] = _SingleCase("Swimmer-v5")
        cases[f"Swimmer-v5 SyncVectorEnv n={sync_robots}"] = _VectorCase(
            lambda: gym.make_vec("Swimmer-v5", num_envs=sync_robots, vectorization_mode="sync"), sync_robots
        )
    envpool_missing = _have_envpool()
    if envpool_missing is None:
        # one env on one thread, and envpool_robots on the threads the batched env may use
        for n, threads in ((1, 1), (envpool_robots, all_threads)):
            cases[f"EnvPool Swimmer-v4 n={n} threads={threads}"] = _EnvPoolCase(n, threads)
    rates: dict[str, list[float]] = {name: [] for name in cases}
    peaks: dict[int, list[float]] = {threads: [] for threads in sorted({1, all_threads})}
    interrupted = None  # where Ctrl-C or SIGTERM stopped the run: what was measured is kept
    complete = 0
    try:
        for name, case in cases.items():
            say(f"warming up: {name}")
            case.run(min(seconds, WARMUP_SECONDS))
        for r in range(repeats):
            for name, case in cases.items():
                say(f"round {r + 1}/{repeats}: {name}")
                rates[name].append(case.run(seconds))
            for threads, rounds in peaks.items():
                say(f"round {r + 1}/{repeats}: matmul peak, {threads} thread(s)")
                rounds.append(matmul_rate(threads, min(seconds, 1.0)))
            complete = r + 1
    except KeyboardInterrupt as err:
        if complete == 0:  # no round has every case: nothing to compare
            _close(cases)
            raise
        interrupted = _stop(
            err, f"in round {complete + 1} of {repeats}; its {complete} complete rounds are kept"
        )
        for kept in (*rates.values(), *peaks.values()):
            del kept[complete:]  # the interrupted round's cases were not all measured
    rows = []
    for name, case in cases.items():
        rows.append(
            {
                "case": name,
                "robots": case.robots,
                "dt": case.dt,
                "sim_s_per_s": statistics.median(rates[name]) * case.dt,
                "steps_per_s": statistics.median(rates[name]),
                "rounds": rates[name],
            }
        )
    shares: dict[str, float] = {}
    ppo_rows: list[dict[str, Any]] = []
    node_rows: list[dict[str, Any]] = []
    phase = "the kernel shares"
    try:
        if interrupted is None:  # else the rounds were cut short: nothing more is measured
            for n in robots:
                name = f"SoftEel-v0 batched n={n} threads=1"
                say(f"kernel share: {name}")
                shares[name] = _kernel_share(cases[name], seconds)
            _close(cases)
            if ppo:
                phase = "the PPO rounds"
                say(f"PPO with the batched env and with SubprocVecEnv, {repeats} interleaved rounds")
                ppo_rows = time_ppo("SoftEel-v0", ppo_n_envs, ppo_timesteps, repeats)
            for N in nodes:
                phase = f"the cost per step at N = {N}"
                say(phase)
                node_rows.append(time_nodes(N, node_robots, seconds))
    except KeyboardInterrupt as err:
        interrupted = _stop(err, f"in {phase}; every measurement before it is kept")
    finally:
        _close(cases)  # closes nothing if closed already

    res: dict[str, Any] = {
        "machine": {
            "platform": platform.platform(),
            "processor": _processor(),
            "cpus": os.cpu_count(),
            "numba_threads": all_threads,
            "threading_layer": _threading_layer(),
            **_code_target(),
        },
        "settings": {
            "seconds": seconds,
            "repeats": repeats,
            "sync_robots": sync_robots,
            "ppo_timesteps": ppo_timesteps,
            "node_robots": node_robots,
            "envpool_robots": envpool_robots,
        },
        "throughput": rows,
        "peak": {
            "matmul_size": MATMUL_SIZE,
            "gflops": {str(t): statistics.median(v) for t, v in peaks.items()},
            "rounds": {str(t): v for t, v in peaks.items()},
        },
        "kernel_share": shares,
        "ppo": ppo_rows,
        "nodes": node_rows,
        "mujoco": mujoco_missing or "installed",
        "envpool": envpool_missing or "installed",
    }
    if interrupted:
        res["interrupted"] = interrupted
    res["ratios"] = _ratios(res)
    res["compute"] = _compute(res)
    return res


def _stop(err: KeyboardInterrupt, where: str) -> dict[str, str]:
    """The results' ``interrupted``: the signal's name (``training.stopped_by``) and ``where``."""
    return {"signal": stopped_by(err).name, "where": where}


def _close(cases: dict[str, Any]) -> None:
    """Close every case's env and take the case out of ``cases``, so that a second call closes nothing."""
    while cases:
        cases.popitem()[1].env.close()


def _compute(res: dict[str, Any]) -> list[dict[str, Any]]:
    """Our plain rows' floating-point work (:data:`FLOPS_PER_STEP`) against the peak measured on their threads."""
    out = []
    for r in res["throughput"]:
        m = _PLAIN_ROW.match(r["case"])
        if m is None:
            continue
        threads = m.group(3) or "1"
        peak = res["peak"]["gflops"].get(threads)
        if peak is None:
            continue
        gflops = r["steps_per_s"] * FLOPS_PER_STEP[m.group(1)] / 1e9
        out.append(
            {
                "case": r["case"],
                "flops_per_step": FLOPS_PER_STEP[m.group(1)],
                "gflops": gflops,
                "peak_gflops": peak,
                "fraction_of_peak": gflops / peak,
            }
        )
    return out


def _processor() -> str:
    """The CPU's model name (Linux's /proc/cpuinfo; elsewhere what ``platform`` knows).

    Runs on different machines differ by more than most changes to the code, so every result
    names its machine.
    """
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def _code_target() -> dict[str, Any]:
    """What numba compiles for, ``llvm_cpu``: LLVM's name for the CPU, whose tuning sets the code's speed."""
    from numba.core.registry import cpu_target

    return {"llvm_cpu": cpu_target.target_context.codegen().magic_tuple()[1]}


def _threading_layer() -> str:
    try:
        return numba.threading_layer()
    except ValueError:
        return "not initialized"


def _row(res: dict[str, Any], case: str) -> dict[str, Any] | None:
    return next((r for r in res["throughput"] if r["case"] == case), None)


def _best(res: dict[str, Any], prefix: str, variant: str = "") -> dict[str, Any] | None:
    """The fastest row whose case starts with ``prefix`` (over thread counts), random actions.

    The env's defaults, or with ``variant`` the rows named ``"<case>, <variant>"``.
    """
    rows = [
        r
        for r in res["throughput"]
        if r["case"].startswith(prefix) and r["case"].partition(", ")[2] == variant
    ]
    return max(rows, key=lambda r: r["steps_per_s"]) if rows else None


def _per_round(ours: dict[str, Any], ref: dict[str, Any], sim: bool) -> list[float]:
    """``ours`` over ``ref`` round by round (round i of every case ran in the same pass), in simulated s if ``sim``."""
    scale = ours["dt"] / ref["dt"] if sim else 1.0
    return [a * scale / b for a, b in zip(ours["rounds"], ref["rounds"], strict=True)]


def _ratios(res: dict[str, Any]) -> dict[str, Any]:
    """The target ratios: single envs in steps/s, 256 robots in simulated s per wall s.

    Each is of the two cases' medians; ``<key>_rounds`` holds it round by round, which shows how
    far the machine's changes of speed within the run moved it.
    """
    out: dict[str, Any] = {}
    swimmer = _row(res, "Swimmer-v5 gym.make")
    pool = _best(res, "EnvPool Swimmer-v4 n=256 ")
    for key, prefix in (
        ("batched256", "SoftEel-v0 batched n=256 "),
        ("worm256", "SoftWorm-v0 batched n=256 "),
    ):
        ours = _best(res, prefix)
        if ours is None:
            continue
        out[f"{key}_case"] = ours["case"]
        for ref, name in ((swimmer, "swimmer"), (pool, "envpool")):
            if ref:
                out[f"{key}_vs_{name}"] = ours["sim_s_per_s"] / ref["sim_s_per_s"]
                out[f"{key}_vs_{name}_steps"] = ours["steps_per_s"] / ref["steps_per_s"]
                out[f"{key}_vs_{name}_rounds"] = _per_round(ours, ref, sim=True)
    if swimmer:
        for key, case in (
            ("single_vs_swimmer", "SoftEel-v0 gym.make"),
            ("worm_single_vs_swimmer", "SoftWorm-v0 gym.make"),
        ):
            row = _row(res, case)
            if row:
                out[key] = row["steps_per_s"] / swimmer["steps_per_s"]
                out[f"{key}_rounds"] = _per_round(row, swimmer, sim=False)
        gait = _row(res, "SoftEel-v0 batched n=256 threads=1, gait actions")
        if gait:
            out["batched256_gait_vs_swimmer"] = gait["sim_s_per_s"] / swimmer["sim_s_per_s"]
        bdf2 = _best(res, "SoftEel-v0 batched n=256 threads=", variant="bdf2")
        if bdf2:
            out["batched256_bdf2_vs_swimmer"] = bdf2["sim_s_per_s"] / swimmer["sim_s_per_s"]
            if pool:
                out["batched256_bdf2_vs_envpool"] = bdf2["sim_s_per_s"] / pool["sim_s_per_s"]
    ppo = {r["kind"]: r for r in res["ppo"]}
    if "batched" in ppo and "subproc" in ppo:
        out["ppo_batched_vs_subproc"] = ppo["batched"]["steps_per_s"] / ppo["subproc"]["steps_per_s"]
        out["ppo_batched_vs_subproc_rounds"] = [
            a / b for a, b in zip(ppo["batched"]["rounds"], ppo["subproc"]["rounds"], strict=True)
        ]
        if "env_steps_per_s" in ppo["batched"]:  # results written before 2026-12-07 21:20 have none
            # the same learn with our step's time taken out of the batched iteration: the rest,
            # the update, the inference and VecNormalize, is SB3's and torch's, paid by both kinds
            batched = 1.0 / ppo["batched"]["steps_per_s"] - 1.0 / ppo["batched"]["env_steps_per_s"]
            out["ppo_env_free_bound"] = 1.0 / ppo["subproc"]["steps_per_s"] / batched
    nodes = res["nodes"]
    if len(nodes) >= 2:
        first, last = nodes[0], nodes[-1]
        out["cost_growth_vs_linear"] = (last["us_per_robot_step"] / first["us_per_robot_step"]) / (
            last["N"] / first["N"]
        )
    return out


def _compute_lines(res: dict[str, Any]) -> list[str]:
    """The report's table of :func:`_compute`'s rows, under the peak measured in the run."""
    peak = res["peak"]["gflops"]
    lines = [
        "",
        "floating-point work against the machine's peak (numpy's float64 matmul in this run: "
        + ", ".join(f"{g:.1f} GFLOP/s on {t} thread(s)" for t, g in peak.items())
        + "):",
        f"  {'case':<48} {'flops/step':>10} {'GFLOP/s':>8} {'of peak':>8}",
    ]
    for r in res["compute"]:
        lines.append(
            f"  {r['case']:<48} {r['flops_per_step']:>10,} {r['gflops']:>8.2f} {100 * r['fraction_of_peak']:>7.1f} %"
        )
    lines.append("  (flops/step counted from the kernels for the default bodies under random actions)")
    return lines


def format_report(res: dict[str, Any]) -> str:
    """The results as plain-text tables with the ratios and the targets."""
    lines = [
        f"machine: {res['machine']['platform']}, {res['machine'].get('processor') or 'CPU not named'}, "
        f"{res['machine']['cpus']} CPUs, numba threads "
        f"{res['machine']['numba_threads']} ({res['machine']['threading_layer']})"
    ]
    if "llvm_cpu" in res["machine"]:  # results written before 2026-12-06 20:20 have no target
        lines[0] += f", code for LLVM's {res['machine']['llvm_cpu']}"
    if "interrupted" in res:
        stop = res["interrupted"]
        lines.append(f"stopped early by {stop['signal']} {stop['where']}")
    for lib, rows in (("mujoco", "Swimmer-v5"), ("envpool", "EnvPool Swimmer-v4")):
        if res.get(lib, "installed") != "installed":
            lines.append(f"{rows} rows skipped: {res[lib]}")
    swimmer = _row(res, "Swimmer-v5 gym.make")
    lines += [
        "",
        f"{'case':<50} {'robot-steps/s':>14} {'dt':>5} {'sim s/wall s':>13} {'vs Swimmer-v5':>14}  rounds",
    ]
    for r in res["throughput"]:
        ratio = f"{r['sim_s_per_s'] / swimmer['sim_s_per_s']:>13.1f}x" if swimmer else f"{'-':>14}"
        rounds = " ".join(f"{x:.0f}" for x in r["rounds"])
        lines.append(
            f"{r['case']:<50} {r['steps_per_s']:>14,.0f} {r['dt']:>5.2f} {r['sim_s_per_s']:>13,.1f} {ratio}  [{rounds}]"
        )
    lines.append("(vs Swimmer-v5: in simulated seconds per wall second)")
    if res.get("compute"):  # results written before the peak was measured have none
        lines += _compute_lines(res)
    if res["kernel_share"]:
        lines += ["", "share of a batched step (1 thread) spent in the compiled call:"]
        for name, share in res["kernel_share"].items():
            lines.append(f"  {name:<40} {100 * share:5.1f} %")
    if res["ppo"]:
        lines += ["", f"{'PPO, environment steps per second':<42} {'n_envs':>7} {'steps/s':>10}"]
        for r in res["ppo"]:
            if "step_steps_per_s" in r:
                if "env_steps_per_s" in r:
                    lines.append(
                        f"{r['kind'] + ': its env alone, random actions':<42} {r['n_envs']:>7} {r['env_steps_per_s']:>10,.0f}"
                    )
                lines.append(
                    f"{r['kind'] + ': stepping, random actions':<42} {r['n_envs']:>7} {r['step_steps_per_s']:>10,.0f}"
                )
                lines.append(
                    f"{r['kind'] + ': stepping + policy inference':<42} {r['n_envs']:>7} {r['inference_steps_per_s']:>10,.0f}"
                )
            rounds = " ".join(f"{x:.0f}" for x in r["rounds"])
            lines.append(
                f"{r['kind'] + ': model.learn':<42} {r['n_envs']:>7} {r['steps_per_s']:>10,.0f}  [{rounds}]"
            )
    if res["nodes"]:
        lines += ["", f"{'N':>4} {'us/robot-step':>14} {'us/node-step':>13} {'Newton its':>11}"]
        for r in res["nodes"]:
            lines.append(
                f"{r['N']:>4} {r['us_per_robot_step']:>14.2f} {r['us_per_node_step']:>13.3f} "
                f"{r['mean_newton_iterations']:>11.2f}"
            )
    ratios = res["ratios"]
    lines += [
        "",
        "targets (ratios measured in this run; 256 robots in simulated s per wall s, single envs in steps/s):",
    ]
    names = {
        "single_vs_swimmer": "SoftEel-v0 single env / Swimmer-v5 single env",
        "worm_single_vs_swimmer": "SoftWorm-v0 single env / Swimmer-v5 single env",
        "batched256_vs_swimmer": "256 batched eels / Swimmer-v5 single env",
        "batched256_vs_envpool": "256 batched eels / EnvPool Swimmer-v4 x256",
        "worm256_vs_swimmer": "256 batched worms / Swimmer-v5 single env",
        "worm256_vs_envpool": "256 batched worms / EnvPool Swimmer-v4 x256",
        "ppo_batched_vs_subproc": "PPO learn steps/s, batched / SubprocVecEnv",
    }
    for key, target in TARGETS.items():
        if key in ratios:
            ok = "met" if ratios[key] >= target else f"MISSED by {100 * (1 - ratios[key] / target):.0f} %"
            steps = f"; in steps/s {ratios[key + '_steps']:.2f}x" if key + "_steps" in ratios else ""
            rounds = ratios.get(key + "_rounds")
            spread = f"; rounds {min(rounds):.2f}x to {max(rounds):.2f}x" if rounds else ""
            if rounds and min(rounds) < target <= max(rounds):  # the machine's noise decides the verdict
                spread += ", on both sides of the line"
            lines.append(f"  {names[key]:<50} {ratios[key]:6.2f}x  (target {target:g}x: {ok}{steps}{spread})")
            if key == "ppo_batched_vs_subproc" and "ppo_env_free_bound" in ratios:
                lines.append(
                    f"    (with our env's step free: {ratios['ppo_env_free_bound']:.2f}x; the rest of a batched"
                    " iteration, the update, the policy's inference and VecNormalize, both kinds pay)"
                )
        else:
            lines.append(f"  {names[key]:<50}   n/a  (not measured)")
    if "batched256_vs_swimmer" in ratios:
        r = ratios["batched256_vs_swimmer"]
        lines.append(
            f"  stretch: 256 batched eels / Swimmer-v5 {r:.2f}x (target {STRETCH:g}x: "
            f"{'met' if r >= STRETCH else f'missed by {100 * (1 - r / STRETCH):.0f} %'}); best: "
            f"{ratios['batched256_case']}"
        )
    if "batched256_gait_vs_swimmer" in ratios:
        lines.append(
            f"    (with the thesis gait instead of random actions: {ratios['batched256_gait_vs_swimmer']:.2f}x)"
        )
    if "batched256_bdf2_vs_swimmer" in ratios:
        pool = ratios.get("batched256_bdf2_vs_envpool")
        lines.append(
            f"    (with integrator.method='bdf2': {ratios['batched256_bdf2_vs_swimmer']:.2f}x"
            + (f"; against EnvPool {pool:.2f}x" if pool else "")
            + ")"
        )
    if "cost_growth_vs_linear" in ratios:
        g = ratios["cost_growth_vs_linear"]
        lines.append(
            f"  cost per robot step, N = {res['nodes'][-1]['N']} vs {res['nodes'][0]['N']}, over linear: "
            f"{g:.2f} ({'no faster than linear' if g <= 1.05 else 'FASTER than linear'})"
        )
    return "\n".join(lines)
