"""Why a policy could not be evaluated, in one line that names the user's own code.

:func:`explain_failure` turns the exception a policy's ``act`` raised while JAX traced,
compiled or ran it (or a host model's callback raised) into its type, message, the
``file.py:LINE`` of the user's code it came from and a hint for the errors tracing commonly
raises; :class:`PolicyError` carries it to the caller (the evaluation, the command line).
"""

from __future__ import annotations

import os
import re
import sysconfig
import traceback

#: Hints for errors a policy's own code commonly raises while JAX traces it.
_HINTS = {
    "TracerBoolConversionError": "a Python `if`/`and`/`or` on an array value: write it with "
    "jnp.where(condition, a, b) (or jax.lax.cond), which JAX can trace",
    "ConcretizationTypeError": "a Python value needed from an array (an `if`, `int()`, a "
    "shape): use jnp.where / jax.lax.cond, and shapes that do not depend on array values",
    "TracerIntegerConversionError": "an array used as a Python int (an index into a list, "
    "range()): index arrays with jnp.take or x[i] on a jnp array",
}


def _is_library(filename: str) -> bool:
    """Whether ``filename`` is this package's, an installed package's or Python's own."""

    name = os.path.abspath(filename)
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the package's folder
    stdlib = os.path.abspath(sysconfig.get_paths()["stdlib"])
    return (
        name.startswith((here + os.sep, stdlib + os.sep))
        or f"{os.sep}site-packages{os.sep}" in name
        or "<frozen" in name
    )


def _user_frame(e: BaseException) -> str:
    """``file.py:LINE`` of the innermost frame of ``e``'s traceback outside JAX, Python's own
    library and this package (the user's own code), or ""."""

    found = ""
    for frame in traceback.extract_tb(e.__traceback__):
        if not _is_library(frame.filename):
            found = f"{os.path.basename(frame.filename)}:{frame.lineno}"
    return found


#: ``  File "PATH", line N`` of a traceback carried as text (an error raised in a host callback
#: reaches the caller as a runtime error whose message holds the callback's traceback)
_TRACEBACK_FILE = re.compile(r'^\s*File "([^"]+)", line (\d+)')


def _callback_failure(message: str) -> tuple[str, str] | None:
    """For the message of an error raised inside a host callback (``jax.pure_callback``, as
    :mod:`lantern_jax.policies.host` uses): the callback's own exception line and the user's
    ``file.py:LINE`` it came from ("" if none); ``None`` for any other message."""
    if "Traceback (most recent call last)" not in message:
        return None
    lines = [ln for ln in message.strip().splitlines() if ln.strip()]
    where = ""
    for ln in lines:
        m = _TRACEBACK_FILE.match(ln)
        if m and not _is_library(m.group(1)):
            where = f"{os.path.basename(m.group(1))}:{m.group(2)}"
    return lines[-1].strip(), where


def explain_failure(e: BaseException) -> str:
    """One line for a policy's failure: the error's type and first (and last) message line,
    where in the user's code it happened, and a hint for the errors tracing commonly raises.
    An error raised inside a host model's callback is reported as that error (its own type,
    message and line in the user's file), not as the runtime's wrapper around it."""
    inner = _callback_failure(str(e))
    if inner is not None:
        why, where = inner
        text = f"in the host callback: {why}"
    else:
        lines = str(e).strip().splitlines() or [""]
        why = lines[0] if len(lines) == 1 else f"{lines[0]} ... {lines[-1]}"
        text = f"{type(e).__name__}: {why}"
        where = _user_frame(e)
    if where:
        text += f" (at {where})"
    hint = _HINTS.get(type(e).__name__)
    if hint is None and isinstance(e, AttributeError) and "'NoneType'" in str(e):
        hint = ("obs.privileged and obs.surround are None unless the policy declares the "
                "'privileged' / 'surround_rig' sensor (Policy(..., sensors=(...)))")  # fmt: skip
    return f"{text}; hint: {hint}" if hint else text


class PolicyError(ValueError):
    """A policy that cannot be evaluated: its ``act`` failed while being traced, compiled or
    run, or returned the wrong shape; the message names the policy."""
