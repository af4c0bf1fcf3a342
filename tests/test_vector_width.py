"""The lane kernels' 512-bit vectors: what LLVM makes of them, in a fresh interpreter.

LLVM tunes for Intel's cores with AVX-512 (``icelake-server`` here) as if they preferred 256-bit
vectors; the lane kernels ask for 512 bits for themselves (``lanes._wide_vectors``), the other
kernels keep LLVM's choice. Only compiled, never run, so any x86-64 host can check it.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import pytest

# machine code for an Intel server core, from two small loops and a lane kernel of the package
PROBE = """
import json
import numpy as np
from numba import njit, typeof
from soft_snake_gym.physics import lanes

@njit
def wide(a, b):
    lanes._wide_vectors()
    for k in range(a.size):
        b[k] = 2.0 * a[k] + b[k]

@njit
def plain(a, b):
    for k in range(a.size):
        b[k] = 2.0 * a[k] + b[k]

a = np.zeros(64)
# compiled for icelake-server's features, which this CPU may not have, so nothing compiled runs
x, p = lanes.allocate.py_func(20), np.zeros((lanes.N_LANE_PRM, lanes.LANES))
energies = njit(error_model="numpy")(lanes.energies.py_func)  # not from the cache: its code is inspected
asm = {}
for name, fn, args in (("wide", wide, (a, a)), ("plain", plain, (a, a)), ("energies", energies, (x, p))):
    sig = tuple(typeof(v) for v in args)
    fn.compile(sig)
    asm[name] = fn.inspect_asm(sig)
print(json.dumps({name: {"zmm": text.count("%zmm"), "ymm": text.count("%ymm")} for name, text in asm.items()}))
"""


ICELAKE_SERVER = ",".join(
    "+" + f
    for f in "sse2 sse3 ssse3 sse4.1 sse4.2 popcnt cx16 avx avx2 fma f16c bmi bmi2 lzcnt movbe "
    "avx512f avx512cd avx512dq avx512bw avx512vl".split()
)


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="an x86-64 CPU name")
def test_lane_kernels_ask_for_512_bit_vectors_where_llvm_prefers_256():
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CPU_")}
    run = subprocess.run(
        [sys.executable, "-c", PROBE],
        # its features named too: without them numba takes the host's, and a CPU without AVX-512
        # (AMD's Zen 3) would leave the kernels no 512-bit registers
        env=env | {"NUMBA_CPU_NAME": "icelake-server", "NUMBA_CPU_FEATURES": ICELAKE_SERVER},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr
    regs = json.loads(run.stdout.splitlines()[-1])
    # the same loop: 256-bit vectors as LLVM chooses, 512-bit ones when the kernel asks
    assert regs["plain"]["zmm"] == 0 and regs["plain"]["ymm"] > 0
    assert regs["wide"]["zmm"] > 0  # (and 256-bit ones for the remainder loops)
    assert regs["energies"]["zmm"] > 0  # a lane kernel of the package
