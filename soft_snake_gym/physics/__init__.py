"""The PDER simulator: numba kernels and the :class:`Simulator` that owns their arrays.

Modules: ``layout`` (index constants, :class:`SimArrays`), ``geometry``, ``forces`` (and their
Jacobians), ``stepper`` (both integrators, stick-slip, :func:`~stepper.simulate`), ``banded``
(the band solver), ``simulator`` (:class:`Simulator`), ``cache`` (numba cache upkeep).

No gymnasium here; environments build on this package.
"""

from soft_snake_gym.physics.layout import SimArrays, allocate_arrays
from soft_snake_gym.physics.simulator import (
    SimulationError,
    Simulator,
    body_from_curvature,
    node_masses,
)

__all__ = [
    "SimArrays",
    "Simulator",
    "SimulationError",
    "allocate_arrays",
    "body_from_curvature",
    "node_masses",
]
