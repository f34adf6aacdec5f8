"""User-facing errors: one line that names the file/field and the problem.

Every error a user can cause (bad file, bad parameter, bad option) is raised as a
:class:`MotorCompError` subclass; the CLI prints ``motor-comp: error: <message>`` and
exits non-zero, never a traceback.  Parameter validation raises :class:`ParameterError`,
which is also a :class:`ValueError` so library users can catch the standard type.
"""
from __future__ import annotations


class MotorCompError(Exception):
    """Base class of errors that are the user's to fix (exit status 2 in the CLI)."""

    exit_code = 2


class ParameterError(MotorCompError, ValueError):
    """A physical or controller parameter is out of its valid range."""


class InputFileError(MotorCompError):
    """A file (MCAP, CSV, MAT, YAML) is missing, empty, truncated, corrupt or lacks data."""


class ModelFileError(MotorCompError):
    """A model file is malformed: unknown effect, missing field, bad value."""


class LimitTripError(MotorCompError):
    """The axis broke a limit (travel, speed, acceleration, voltage, tracking error).

    The controller stopped it (0 V); the message names the limit, the value and the
    time.  Exit status 3, distinct from a user error (2).
    """

    exit_code = 3


def check_finite(name: str, value: float) -> float:
    """Return ``float(value)`` or raise :class:`ParameterError` naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f'{name} must be a number, got {value!r}') from None
    if v != v or v in (float('inf'), float('-inf')):
        raise ParameterError(f'{name} must be finite, got {value!r}')
    return v


def check_positive(name: str, value: float) -> float:
    """Return ``value`` if finite and > 0, else raise :class:`ParameterError`."""
    v = check_finite(name, value)
    if v <= 0.0:
        raise ParameterError(f'{name} must be > 0, got {v:g}')
    return v


def check_nonnegative(name: str, value: float) -> float:
    """Return ``value`` if finite and >= 0, else raise :class:`ParameterError`."""
    v = check_finite(name, value)
    if v < 0.0:
        raise ParameterError(f'{name} must be >= 0, got {v:g}')
    return v
