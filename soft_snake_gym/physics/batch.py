"""Many robots stepped by one compiled call: the physics of the batched vector environment.

A :class:`BatchSimulator` stacks the arrays of ``n`` robots along a leading axis; each robot
is an ordinary :class:`~soft_snake_gym.physics.Simulator` over views of those arrays (so
``reset``, ``set_state``, ``set_config`` and every observable work per robot), and
:meth:`BatchSimulator.step` advances all of them with :func:`simulate_batch`, a ``prange``
loop over the same :func:`~soft_snake_gym.physics.kernels.simulate` kernel that a single
simulator calls. Robots are independent, so the result is bitwise the same for any number of
threads and equal to stepping each robot alone.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from soft_snake_gym.params import SimConfig
from soft_snake_gym.physics import banded
from soft_snake_gym.physics import kernels as K
from soft_snake_gym.physics.cache import drop_stale_cache
from soft_snake_gym.physics.simulator import Simulator, allocate_arrays

__all__ = ["BatchSimulator", "simulate_batch"]

drop_stale_cache(__file__, [K.__file__, banded.__file__])  # simulate_batch embeds their code


@njit(cache=True, parallel=True, error_model="numpy")
def simulate_batch(q, v, kbar, lbar, u_k, u_l, prm, buf, J, ibuf, out, active, status, n_steps):
    """Advance every robot ``i`` with ``active[i]`` by ``n_steps``; its status into ``status[i]``."""
    for i in prange(q.shape[0]):
        if active[i]:
            status[i] = K.simulate(q[i], v[i], kbar[i], lbar[i], u_k[i], u_l[i], prm[i], buf[i],
                                   J[i], ibuf[i], out[i], n_steps)


class BatchSimulator:
    """``n`` robots of the same N, each with its own parameters, stepped together.

    Args:
        config: the parameters every robot starts with (change one with
            ``batch.sims[i].set_config``).
        n: number of robots.
        num_threads: threads for the batched step (default: numba's default, the core count).

    Attributes:
        sims: the robots, as :class:`Simulator` objects over views of the stacked arrays.
        q, v, kbar, lbar: stacked state, (n, 2N), (n, 2N), (n, N-2), (n, N-1).
    """

    def __init__(self, config: SimConfig | None = None, n: int = 1, num_threads: int | None = None) -> None:
        config = SimConfig() if config is None else config
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n = {n!r} robots: need an integer >= 1")
        max_threads = numba.config.NUMBA_NUM_THREADS
        if num_threads is not None and (
            isinstance(num_threads, bool) or not isinstance(num_threads, (int, np.integer))
            or not 1 <= num_threads <= max_threads
        ):
            raise ValueError(f"num_threads = {num_threads!r}: need an integer in [1, {max_threads}]")
        self.n = int(n)
        self.N = config.rod.N
        self.num_threads = int(num_threads or max_threads)
        self._arrays = allocate_arrays(self.N, (self.n,))
        self.q, self.v, self.kbar, self.lbar = self._arrays[:4]
        self.sims = [Simulator(config, _arrays=tuple(a[i] for a in self._arrays)) for i in range(self.n)]
        self.status = np.zeros(self.n, dtype=np.int64)
        self._all = np.ones(self.n, dtype=np.bool_)
        self._zero_k = np.zeros((self.n, self.N - 2))
        self._zero_l = np.zeros((self.n, self.N - 1))

    def step(self, u_k: np.ndarray | None = None, u_l: np.ndarray | None = None,
             active: np.ndarray | None = None, n_steps: int = 1) -> np.ndarray:
        """Advance the robots in ``active`` (default all) with inputs ``u_k`` (n, N-2) and
        ``u_l`` (n, N-1) held over ``n_steps`` steps. Returns a bool array: which succeeded
        (inactive robots count as succeeded); a failed robot's ``sims[i].failure`` is set."""
        u_k = self._zero_k if u_k is None else self._check(u_k, "u_k", self.N - 2)
        u_l = self._zero_l if u_l is None else self._check(u_l, "u_l", self.N - 1)
        active = self._all if active is None else np.ascontiguousarray(active, dtype=np.bool_)
        for i in np.flatnonzero(active):
            if self.sims[i].failure is not None:
                raise RuntimeError(
                    f"robot {i} failed ({self.sims[i].failure}); reset it before stepping it again"
                )
        self.status[:] = K.OK
        numba.set_num_threads(self.num_threads)
        simulate_batch(*self._arrays[:4], u_k, u_l, *self._arrays[4:], active, self.status, n_steps)
        failed = np.flatnonzero(self.status != K.OK)
        for i in failed:
            self.sims[i].failure = K.STATUS_REASONS[self.status[i]]
        return self.status == K.OK

    def _check(self, u: np.ndarray, name: str, width: int) -> np.ndarray:
        if not (isinstance(u, np.ndarray) and u.dtype == np.float64 and u.flags.c_contiguous):
            u = np.ascontiguousarray(u, dtype=np.float64)
        if u.shape != (self.n, width):
            raise ValueError(f"{name} has shape {u.shape}; expected ({self.n}, {width})")
        if not np.isfinite(u).all():
            rows = np.flatnonzero(~np.isfinite(u).all(axis=1))
            raise ValueError(f"{name} has non-finite entries for robots {rows.tolist()[:8]}")
        return u
