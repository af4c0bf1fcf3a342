"""``SOFT_SNAKE_GYM_VECTOR_BITS``: what numba's code generator is given, in a fresh interpreter each."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from llvmlite import binding

AVX512 = binding.get_host_cpu_features().get("avx512f", False)

# the features numba's JIT compiles with: those of its target machine, made at its first function
PROBE = """
import os, soft_snake_gym
from numba.core.registry import cpu_target
print(cpu_target.target_context.codegen().magic_tuple()[2])
print(os.environ.get("NUMBA_CPU_FEATURES", "unset"))
"""


# what a benchmark's results record of it
BENCHMARK_PROBE = """
import json
from soft_snake_gym.benchmark import _code_target
print(json.dumps(_code_target()))
"""


def _import(probe: str = PROBE, **env: str) -> subprocess.CompletedProcess:
    """Run ``probe`` in a new interpreter, NUMBA_CPU_* and the variable unset, ``env`` added."""
    base = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_CPU_", "SOFT_SNAKE_GYM_VECTOR"))}
    return subprocess.run(
        [sys.executable, "-c", probe], env=base | env, capture_output=True, text=True, timeout=120
    )


def test_by_default_numba_compiles_for_the_host_as_it_chooses():
    run = _import()
    assert run.returncode == 0, run.stderr
    features, variable = run.stdout.split()
    assert "prefer-256-bit" not in features and variable == "unset"


@pytest.mark.skipif(not AVX512, reason="the host has no AVX-512: the variable changes nothing")
def test_512_bits_reach_numba_before_the_package_makes_a_function():
    run = _import(SOFT_SNAKE_GYM_VECTOR_BITS="512")
    assert run.returncode == 0, run.stderr
    features, variable = run.stdout.split()
    assert features.endswith(",-prefer-256-bit") and "+avx512f" in features
    assert variable == features  # and the children inherit it


@pytest.mark.skipif(not AVX512, reason="the host has no AVX-512: the variable changes nothing")
def test_the_users_own_numba_cpu_settings_win():
    run = _import(SOFT_SNAKE_GYM_VECTOR_BITS="512", NUMBA_CPU_NAME="generic")
    assert run.returncode == 0, run.stderr
    assert "prefer-256-bit" not in run.stdout


def test_a_width_other_than_256_or_512_is_refused_at_import():
    run = _import(SOFT_SNAKE_GYM_VECTOR_BITS="1024")
    assert run.returncode != 0
    assert "SOFT_SNAKE_GYM_VECTOR_BITS = '1024': use 256 (the default) or 512" in run.stderr


@pytest.mark.skipif(not AVX512, reason="the host has no AVX-512: the variable changes nothing")
def test_a_benchmark_records_whether_it_measured_512_bit_vectors():
    runs = [_import(BENCHMARK_PROBE), _import(BENCHMARK_PROBE, SOFT_SNAKE_GYM_VECTOR_BITS="512")]
    assert all(run.returncode == 0 for run in runs), [run.stderr for run in runs]
    default, wide = (json.loads(run.stdout) for run in runs)
    assert default["vectors_512"] is False and wide["vectors_512"] is True
    assert default["llvm_cpu"] == wide["llvm_cpu"] == binding.get_host_cpu_name()
