"""``SOFT_SNAKE_GYM_VECTOR_BITS=512``: numba's LLVM asked for 512-bit vectors, before anything compiles.

LLVM tunes for Intel's cores with AVX-512 as if they preferred 256-bit vectors, so the batched
kernels' lane loops (``physics.lanes``: sixteen robots an instruction) run four doubles an
instruction where the registers hold eight. With ``-prefer-256-bit`` added to the host's
features they run eight. Measured on an Intel Xeon with AVX-512 (docs/performance.md, "512-bit
vectors"): the compiled call of 256 eels 1.06× faster on one thread and 1.07× on two, of 256
worms 1.03× and 1.02×, but the single envs' step 0.94× and 0.92×, and PPO's rollout on 8
batched eels 0.99×. So it is a choice, not the default: for large batches on such a CPU. The
numbers are the same, bit for bit: the kernels are compiled without reassociation, so a wider
vector does more of the same operations at once.

numba takes its CPU's features from ``NUMBA_CPU_FEATURES`` (``numba.config.CPU_FEATURES``) when it
makes its first function, so :func:`apply_vector_bits` runs once, at the package's import, before
any of the package's functions is made: with the variable at 512 it sets ``NUMBA_CPU_FEATURES``
for the whole process and its children, for any numba code (numba caches such code apart from
code for the default features). It changes nothing where the user has set ``NUMBA_CPU_FEATURES``
or ``NUMBA_CPU_NAME``, on a CPU without AVX-512, or where numba made a function before the
package's import.
"""

from __future__ import annotations

import os

from llvmlite import binding
from numba.core import config

__all__ = ["VECTOR_BITS", "WIDE_FEATURE", "apply_vector_bits", "asks_512_bits"]

VECTOR_BITS = "SOFT_SNAKE_GYM_VECTOR_BITS"
"""The environment variable: 256 (the default, LLVM's choice) or 512."""
WIDE_FEATURE = "-prefer-256-bit"
"""The LLVM feature that 512 adds to the host's: LLVM then uses the registers' whole 512 bits."""


def asks_512_bits(features: str) -> bool:
    """True if an LLVM feature string (numba's code generator's, say) holds :data:`WIDE_FEATURE`."""
    return WIDE_FEATURE in features.split(",")


def apply_vector_bits() -> bool:
    """Set ``NUMBA_CPU_FEATURES`` to the host's features and ``-prefer-256-bit`` if ``VECTOR_BITS`` is 512.

    Returns:
        True if it set the variable.

    Raises:
        ValueError: the variable is neither 256 nor 512.
    """
    env = os.environ
    bits = env.get(VECTOR_BITS) or "256"
    if bits not in ("256", "512"):
        raise ValueError(
            f"{VECTOR_BITS} = {bits!r}: use 256 (the default) or 512 (large batches with AVX-512)"
        )
    if bits == "256" or "NUMBA_CPU_FEATURES" in env or "NUMBA_CPU_NAME" in env:
        return False
    features = binding.get_host_cpu_features()
    if not features.get("avx512f", False):
        return False
    env["NUMBA_CPU_FEATURES"] = f"{features.flatten()},{WIDE_FEATURE}"
    config.reload_config()  # numba read its variables at its import
    return True
