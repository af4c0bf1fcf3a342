"""soft_snake_gym.

Soft segmented robots (an eel that swims, a worm that inches) as a numba-compiled planar discrete
elastic rod, with Gymnasium environments on top.
"""

from soft_snake_gym.vector_width import apply_vector_bits

apply_vector_bits()  # SOFT_SNAKE_GYM_VECTOR_BITS, before any kernel is made (soft_snake_gym/vector_width.py)

from soft_snake_gym.envs import InchEnv, SwimEnv, register_envs  # noqa: E402
from soft_snake_gym.params import Fluid, Ground, Integrator, Rod, SimConfig  # noqa: E402
from soft_snake_gym.physics import SimulationError, Simulator, body_from_curvature  # noqa: E402

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
