"""Array checks of the ``validate()`` methods (NumPy, outside ``jit``): each raises
:class:`ValueError` naming the offending field, e.g. ``"ActorScript.extent: ..."``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from lantern_jax.core.constants import MAX_SEED


def _arr(name: str, x: Any) -> np.ndarray:
    try:
        return np.asarray(x)
    except Exception as err:  # pragma: no cover - defensive
        raise ValueError(f"{name}: cannot convert to an array ({err})") from err


def check_shape(name: str, x: Any, shape: tuple) -> np.ndarray:
    """Check that ``x`` has ``shape`` (``None`` entries match any size) and return it as numpy.

    Raises:
        ValueError: naming ``name`` when the rank or a fixed dimension differs.
    """
    a = _arr(name, x)
    if a.ndim != len(shape) or any(
        s is not None and s != d for s, d in zip(shape, a.shape, strict=True)
    ):
        want = "(" + ", ".join("?" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name}: expected shape {want}, got {a.shape}")
    return a


def check_finite(name: str, x: Any, mask: Any = None) -> np.ndarray:
    """Check that every (masked) entry of ``x`` is finite; raise ``ValueError`` naming ``name``."""
    a = _arr(name, x).astype(np.float64)
    if mask is not None:
        m = np.broadcast_to(
            np.asarray(mask, bool).reshape(np.shape(mask) + (1,) * (a.ndim - np.ndim(mask))),
            a.shape,
        )
        a = np.where(m, a, 0.0)
    if not np.all(np.isfinite(a)):
        idx = np.argwhere(~np.isfinite(a))[0].tolist()
        raise ValueError(f"{name}: contains NaN or inf (first at index {idx})")
    return a


def check_nonneg(name: str, x: Any, mask: Any = None) -> None:
    """Check that every (masked) entry of ``x`` is >= 0; raise ``ValueError`` naming ``name``."""
    a = check_finite(name, x, mask)
    if np.any(a < 0):
        idx = np.argwhere(a < 0)[0].tolist()
        raise ValueError(f"{name}: must be non-negative (first negative at index {idx})")


def check_seed(name: str, value: Any) -> int:
    """A generator seed: a whole number in ``0 .. MAX_SEED`` (not a bool); returns it as int.

    Raises:
        ValueError: naming ``name`` and the value.
    """
    ok = isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)
    if not ok or not 0 <= int(value) <= MAX_SEED:
        raise ValueError(f"{name}: expected a whole number in 0 .. 2**63 - 1, got {value!r}")
    return int(value)
