"""The PDER simulator: numba kernels and the :class:`Simulator` that owns their arrays.

No gymnasium here; environments build on this package.
"""

from soft_snake_gym.physics.simulator import (
    SimulationError,
    Simulator,
    body_from_curvature,
    node_masses,
)

__all__ = ["Simulator", "SimulationError", "body_from_curvature", "node_masses"]
