"""Ray for the package's parallel work: connect to a cluster, set up its workers, run tasks.

Ray is an optional dependency (the ``ray`` extra: ``pip install "soft-snake-gym[ray]"``) and
takes about a second to import, so it is imported inside the functions, never at module level.
The commands that can run on Ray (``soft-snake sweep --backend ray``, ``soft-snake train --seeds
... --backend ray``) go through :func:`connect` and :func:`imap_unordered`; the rest of the
package never touches Ray.

Every worker process of a job started by :func:`connect` behaves (:func:`worker_runtime_env`):

- its numba, OpenMP, MKL, OpenBLAS and torch threads are capped to the task's CPU share
  (``task_cpus``, one by default), so that N tasks on N CPUs do not start N x cores threads;
- it uses the numba disk cache of the package (the ``__pycache__`` folders beside its sources,
  shared by every worker of a machine, or ``NUMBA_CACHE_DIR`` when the driver sets it), so a
  kernel is compiled once per machine, not once per task;
- it imports the package and registers the env ids before its first task (Gymnasium's
  registry lives in each process).
"""

from __future__ import annotations

import contextlib
import os
import socket
from collections.abc import Callable, Iterable, Iterator
from types import ModuleType
from typing import Any

from soft_snake_gym.envs import register_envs

__all__ = [
    "RAY_INSTALL",
    "RayNotInstalled",
    "THREAD_VARIABLES",
    "connect",
    "connected",
    "imap_unordered",
    "import_ray",
    "setup_worker",
    "worker_runtime_env",
]

RAY_INSTALL = 'pip install "soft-snake-gym[ray]"'
"""The install line of the optional dependencies that Ray features need."""

THREAD_VARIABLES = (
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "NUMBA_NUM_THREADS",
    "SOFT_SNAKE_TASK_CPUS",
)
"""Environment variables set to the task's CPU share in every Ray worker (torch reads OMP's)."""

CONNECT_TIMEOUT = 3.0
"""Seconds to wait for a cluster's address to answer before calling it unreachable."""


class RayNotInstalled(ImportError):
    """Ray (or another package of the ``ray`` extra) is missing; the message names the install line."""


def import_ray() -> ModuleType:
    """The ``ray`` module, or :class:`RayNotInstalled` naming the install line."""
    try:
        import ray  # here, not above: optional, and about a second to import
    except ImportError:
        raise RayNotInstalled(
            f"the Ray backend needs Ray, which is not installed; install it with: {RAY_INSTALL}"
        ) from None
    return ray


def worker_runtime_env(task_cpus: int = 1) -> dict[str, Any]:
    """The ``runtime_env`` of a job whose tasks each get ``task_cpus`` CPUs.

    Thread caps for numba, OpenMP, MKL, OpenBLAS and torch (:data:`THREAD_VARIABLES`), the
    driver's ``NUMBA_CACHE_DIR`` if it has one, and :func:`setup_worker` as the worker process
    setup hook.

    Raises:
        ValueError: ``task_cpus`` below 1.
    """
    if int(task_cpus) != task_cpus or task_cpus < 1:
        raise ValueError(f"task_cpus = {task_cpus!r} must be a whole number of CPUs, at least 1")
    env_vars = {name: str(int(task_cpus)) for name in THREAD_VARIABLES}
    if os.environ.get("NUMBA_CACHE_DIR"):
        env_vars["NUMBA_CACHE_DIR"] = os.environ["NUMBA_CACHE_DIR"]
    return {"env_vars": env_vars, "worker_process_setup_hook": f"{__name__}.setup_worker"}


def setup_worker() -> None:
    """Ray's worker process setup hook: import the package (env ids) and cap numba's threads.

    The environment variables of :func:`worker_runtime_env` are already set when it runs; numba
    reads ``NUMBA_NUM_THREADS`` when first imported, and this caps a numba imported earlier too.
    """
    import numba

    register_envs()  # SoftEel-v0 and SoftWorm-v0 in this worker's Gymnasium registry
    cpus = int(os.environ.get("SOFT_SNAKE_TASK_CPUS", "1"))
    numba.set_num_threads(max(1, min(cpus, numba.config.NUMBA_NUM_THREADS)))


def _check_reachable(address: str) -> None:
    """Raise ``ValueError`` unless ``host:port`` (after an optional ``ray://``) accepts a connection."""
    hostport = address.split("://", 1)[-1]
    host, sep, port = hostport.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ValueError(
            f"--address {address!r} is not host:port (e.g. 127.0.0.1:6379) or 'auto'; "
            "the head node's address is printed by `ray start --head`"
        )
    try:
        with socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT):
            pass
    except OSError as err:
        raise ValueError(
            f"--address {address!r}: no Ray cluster answers there ({err.strerror or err}); start one "
            "with `ray start --head` and pass the address it prints, or omit --address for a local Ray"
        ) from None


def connect(address: str | None = None, num_cpus: int | None = None, task_cpus: int = 1) -> ModuleType:
    """Connect this process to Ray (a new local Ray, or an existing cluster); returns ``ray``.

    Already connected: returns ``ray`` as it is (the existing job's settings stay).

    Args:
        address: None starts a new local Ray for this process (even if a cluster runs on this
            machine); ``"host:port"`` joins the cluster
            whose head node is there (``ray start --head`` prints it); ``"auto"`` joins the
            cluster started on this machine.
        num_cpus: CPUs of a local Ray (default: every core); ignored with an address.
        task_cpus: CPUs of each task, the workers' thread cap (:func:`worker_runtime_env`).

    Raises:
        RayNotInstalled: Ray is not installed.
        ValueError: ``address`` is not an address, or no cluster answers there (within
            :data:`CONNECT_TIMEOUT` seconds).
    """
    ray = import_ray()
    if ray.is_initialized():
        return ray
    runtime_env = worker_runtime_env(task_cpus)
    if address is None:
        if num_cpus is not None and (int(num_cpus) != num_cpus or num_cpus < 1):
            raise ValueError(f"num_cpus = {num_cpus!r} must be a whole number, at least 1 (or None)")
        ray.init(  # "local": a new Ray even where `ray start` left a cluster to find
            address="local",
            num_cpus=num_cpus,
            runtime_env=runtime_env,
            log_to_driver=False,
            include_dashboard=False,
        )
        return ray
    if address != "auto":
        _check_reachable(address)
    try:
        ray.init(address=address, runtime_env=runtime_env, log_to_driver=False)
    except ConnectionError as err:
        raise ValueError(
            f"--address {address!r}: {str(err).strip().splitlines()[0]} (start one with `ray start --head`, "
            "or omit --address for a local Ray)"
        ) from None
    return ray


@contextlib.contextmanager
def connected(address: str | None = None, num_cpus: int | None = None, task_cpus: int = 1):
    """:func:`connect` as a context: yields ``ray``, and disconnects at the end if it connected."""
    ray = import_ray()
    was = ray.is_initialized()
    ray = connect(address, num_cpus, task_cpus)
    try:
        yield ray
    finally:
        if not was:
            ray.shutdown()


def imap_unordered(
    fn: Callable[..., Any],
    args: Iterable[tuple[Any, ...]],
    num_cpus: float = 1,
    max_retries: int = 3,
) -> Iterator[tuple[int, Any]]:
    """Run ``fn(*a)`` for each ``a`` of ``args`` as Ray tasks; yield ``(index, result)`` as each finishes.

    Needs a connected Ray (:func:`connect`). ``fn`` must be importable by the workers (a
    module-level function of the package). A task whose worker process dies (killed, out of
    memory, its node lost) is run again, up to ``max_retries`` times, and yielded once. If the
    consumer stops (an exception, Ctrl-C, ``close()``), the unfinished tasks are cancelled.
    """
    ray = import_ray()
    remote = ray.remote(fn).options(num_cpus=num_cpus, max_retries=max_retries)
    index = {}
    for i, a in enumerate(args):
        index[remote.remote(*a)] = i
    pending = list(index)
    try:
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                yield index[ref], ray.get(ref)
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
