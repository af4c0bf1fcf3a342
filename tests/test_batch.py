"""The one batched loop steps every robot exactly as a lone simulator would.

The loop is ``task.step_units`` on each of the vector env's threads (``vector._step``), tested over
the public :class:`RobotBatch`.
"""

from __future__ import annotations

import gc

import gymnasium as gym
import numpy as np
from numba.core.runtime import _nrt_python, rtsys

from soft_snake_gym import Fluid, Rod, SimConfig, Simulator
from soft_snake_gym.envs import SoftVectorEnv
from soft_snake_gym.envs.task import CRAWL_MIN, R_REWARD


def test_batch_matches_single_simulators_bit_for_bit_with_any_thread_count():
    n, steps = 18, 120  # a block of 16 robots stepped together and two one by one
    rng = np.random.default_rng(5)
    A = rng.uniform(-1, 1, (steps, n, 8))
    configs = [SimConfig(fluid=Fluid(rho=900 + 50 * i), rod=Rod(E_bend=1e5 * (i + 1))) for i in range(n)]
    active = np.ones(n, dtype=bool)
    results, inputs = [], []
    for threads in (1, 2):
        venv = SoftVectorEnv("SoftEel-v0", n, num_threads=threads, max_episode_steps=None)
        venv.reset(seed=0)
        batch = venv.batch
        x0 = [sim.x for sim in batch.sims]
        for i, cfg in enumerate(configs):
            batch.sims[i].set_config(cfg)
        u_k = []
        for s in range(steps):
            terminated, _ = venv.advance(A[s], active)
            assert not terminated.any()
            u_k.append(batch.task.uk.copy())  # the inputs the kernel made of the actions
        results.append((batch.sim.q.copy(), batch.sim.v.copy()))
        inputs.append(u_k)
    assert all(np.array_equal(a, b) for a, b in zip(*inputs, strict=True))
    singles = [Simulator(cfg) for cfg in configs]
    for i, sim in enumerate(singles):
        sim.reset(x=x0[i])
    for s in range(steps):
        for i, sim in enumerate(singles):
            sim.step(u_k=inputs[0][s][i])
    for q, v in results:
        assert np.array_equal(q, np.stack([s.arrays.q for s in singles]))
        assert np.array_equal(v, np.stack([s.arrays.v for s in singles]))
    assert not np.array_equal(results[0][0][0], results[0][0][1])  # the robots really differ


def _alive_after(env, rng: np.random.Generator, steps: int) -> int:
    """How many of numba's allocations are alive (allocated, not yet freed) after ``steps`` steps of ``env``."""
    for _ in range(steps):
        env.step(rng.uniform(-0.5, 0.5, env.action_space.shape))
    gc.collect()
    stats = rtsys.get_allocation_stats()
    return stats.mi_alloc - stats.mi_free


def test_the_kernels_compiled_without_reference_counts_leak_nothing_and_free_nothing():
    """Numba's allocation statistics over the steps of the single envs and of the batched ones.

    The hot kernels are compiled with ``_nrt=False`` (docs/architecture.md): one that kept an
    array some callee allocated would leak it every step, one that let go of a reference it
    never took would free what its caller still holds. Either changes how many of numba's
    allocations are alive (allocated and not yet freed) after 10 more steps.
    """
    envs = [
        gym.make("SoftEel-v0"),
        gym.make("SoftWorm-v0"),
        SoftVectorEnv("SoftEel-v0", 32, num_threads=1),  # two blocks of eels
        SoftVectorEnv("SoftWorm-v0", CRAWL_MIN, num_threads=1),  # the worms in lanes
    ]
    _nrt_python.memsys_enable_stats()
    try:
        for env in envs:
            env.reset(seed=0)
            rng = np.random.default_rng(0)
            alive = _alive_after(env, rng, 5)  # compiled, and the first infos built
            assert _alive_after(env, rng, 10) == alive, env
    finally:
        _nrt_python.memsys_disable_stats()


def test_robots_are_views_of_the_batch_arrays():
    venv = SoftVectorEnv("SoftEel-v0", 3)
    venv.reset(seed=1)
    batch = venv.batch
    assert np.shares_memory(batch.sims[2].arrays.q, batch.sim.q[2])
    assert np.shares_memory(batch.sims[2].arrays.f, batch.sim.f[2])  # the block the kernels step
    assert np.array_equal(batch.sims[2].x.ravel(), batch.sim.q[2])
    assert np.array_equal(batch.time, [0.0, 0.0, 0.0])
    venv.step(np.zeros((3, 8)))
    assert np.allclose(batch.time, batch.sims[0].h) and batch.sims[1].time == batch.time[1]
    assert np.array_equal(venv.rewards, batch.task.rs[:, R_REWARD])


def test_inactive_robots_stay_put_and_failures_are_per_robot():
    venv = SoftVectorEnv("SoftWorm-v0", 3)
    venv.reset(seed=0)
    batch = venv.batch
    v = np.zeros((10, 2))
    v[5, 1] = 1e3  # robot 1's node 5 leaves the body: runaway stretch
    batch.sims[1].set_state(v=v)
    q0 = batch.sim.q.copy()
    terminated, truncated = venv.advance(np.full((3, 9), 0.5), np.array([True, True, False]))
    assert terminated.tolist() == [False, True, False] and not truncated.any()
    assert venv.envs[1].failure == "runaway_stretch" and batch.sims[1].failure == "runaway_stretch"
    assert venv.envs[0].failure is None
    assert np.array_equal(batch.sim.q[2], q0[2]) and not np.array_equal(batch.sim.q[0], q0[0])
    venv.reset_robot(1, seed=0)
    assert venv.envs[1].failure is None
    terminated, _ = venv.advance(np.zeros((3, 9)), np.ones(3, dtype=bool))
    assert not terminated.any()
