"""The batched physics steps every robot exactly as a lone simulator would."""

from __future__ import annotations

import numpy as np
import pytest

from soft_snake_gym import Fluid, Rod, SimConfig, Simulator
from soft_snake_gym.physics.batch import BatchSimulator


def test_batch_matches_single_simulators_bit_for_bit_with_any_thread_count():
    n, steps = 6, 120
    rng = np.random.default_rng(5)
    U = rng.normal(0, 0.8, (steps, n, 8))
    configs = [SimConfig(fluid=Fluid(rho=900 + 50 * i), rod=Rod(E_bend=1e5 * (i + 1))) for i in range(n)]
    results = []
    for threads in (1, 2):
        batch = BatchSimulator(SimConfig(), n, num_threads=threads)
        for i, cfg in enumerate(configs):
            batch.sims[i].set_config(cfg)
        for s in range(steps):
            assert batch.step(u_k=U[s]).all()
        results.append((batch.q.copy(), batch.v.copy()))
    singles = [Simulator(cfg) for cfg in configs]
    for s in range(steps):
        for i, sim in enumerate(singles):
            sim.step(u_k=U[s, i])
    for q, v in results:
        assert np.array_equal(q, np.stack([s._q for s in singles]))
        assert np.array_equal(v, np.stack([s._v for s in singles]))
    assert not np.array_equal(results[0][0][0], results[0][0][1])  # the robots really differ


def test_inactive_robots_stay_put_and_failures_are_per_robot():
    batch = BatchSimulator(SimConfig(), 3)
    u_l = np.zeros((3, 9))
    u_l[1, 4] = 200.0  # robot 1 overstretches
    q0 = batch.q.copy()
    ok = batch.step(u_l=u_l, active=np.array([True, True, False]))
    assert ok.tolist() == [True, False, True]
    assert batch.sims[1].failure == "runaway_stretch" and batch.sims[0].failure is None
    assert np.array_equal(batch.q[2], q0[2])
    with pytest.raises(RuntimeError, match="robot 1 failed"):
        batch.step()
    batch.sims[1].reset()
    assert batch.step().all()


def test_bad_batch_arguments_are_explained():
    with pytest.raises(ValueError, match=r"n = 0 robots"):
        BatchSimulator(SimConfig(), 0)
    with pytest.raises(ValueError, match=r"num_threads = 0"):
        BatchSimulator(SimConfig(), 2, num_threads=0)
    batch = BatchSimulator(SimConfig(), 2)
    with pytest.raises(ValueError, match=r"u_k has shape \(8,\); expected \(2, 8\)"):
        batch.step(u_k=np.zeros(8))
    with pytest.raises(ValueError, match=r"non-finite entries for robots \[1\]"):
        batch.step(u_k=np.array([[0.0] * 8, [np.nan] * 8]))
