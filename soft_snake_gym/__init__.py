"""soft_snake_gym: soft segmented robots (an eel that swims, a worm that inches) as a
numba-compiled planar discrete elastic rod, with Gymnasium environments on top."""

from soft_snake_gym.params import Fluid, Ground, Integrator, Rod, SimConfig
from soft_snake_gym.physics import Simulator, SimulationError, body_from_curvature

__version__ = "0.1.0"

__all__ = [
    "Fluid",
    "Ground",
    "Integrator",
    "Rod",
    "SimConfig",
    "Simulator",
    "SimulationError",
    "body_from_curvature",
    "__version__",
]
