"""soft_snake_gym.

Soft segmented robots (an eel that swims, a worm that inches) as a numba-compiled planar discrete
elastic rod, with Gymnasium environments on top.
"""

from soft_snake_gym.envs import InchEnv, SwimEnv, register_envs
from soft_snake_gym.params import Fluid, Ground, Integrator, Rod, SimConfig
from soft_snake_gym.physics import SimulationError, Simulator, body_from_curvature

register_envs()  # SoftEel-v0, SoftWorm-v0; gym.make("soft_snake_gym:SoftEel-v0") relies on it

__version__ = "0.1.0"

__all__ = [
    "Fluid",
    "Ground",
    "InchEnv",
    "Integrator",
    "Rod",
    "SimConfig",
    "Simulator",
    "SimulationError",
    "SwimEnv",
    "body_from_curvature",
    "__version__",
]
