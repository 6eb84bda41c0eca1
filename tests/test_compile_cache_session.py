"""The test session's persistent compilation cache (set up in ``conftest.py``): on from the
first compile, keeping every program, and exported to the subprocesses the tests start."""

from __future__ import annotations

import os
import time
from pathlib import Path

import jax
import jax.numpy as jnp
from conftest import COMPILE_CACHE_DIR


def test_session_cache_is_on_and_exported():
    assert jax.config.jax_enable_compilation_cache
    assert jax.config.jax_compilation_cache_dir == COMPILE_CACHE_DIR
    assert jax.config.jax_persistent_cache_min_compile_time_secs == 0.0
    # subprocesses (command-line tests, notebook kernels) read the same settings
    assert os.environ["JAX_COMPILATION_CACHE_DIR"] == COMPILE_CACHE_DIR
    assert float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]) == 0.0


def test_a_small_program_is_written_to_the_cache():
    """A program far below JAX's default 1-s threshold is kept (a new constant: a new key)."""
    folder = Path(COMPILE_CACHE_DIR)
    before = set(folder.iterdir()) if folder.exists() else set()
    c = float(time.time_ns() % 1_000_003) + 0.5
    jax.block_until_ready(jax.jit(lambda x: x * c + 1.0)(jnp.arange(3.0)))
    assert set(folder.iterdir()) - before
