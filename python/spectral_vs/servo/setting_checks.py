"""The checks of the servo's settings groups: each raises ``ValueError`` (a wrong type:
``TypeError``) naming the field and its limit."""

from __future__ import annotations

import math
import numbers
from typing import Any


def check_number(params: Any, name: str) -> Any:
    """The setting ``name`` of ``params``, refused unless a real number (TypeError naming
    it): ``lambda_t='2'`` would otherwise fail in a comparison that names nothing."""
    value = getattr(params, name)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number, got {value!r} ({type(value).__name__})")
    return value


def check_positive(params: Any, names: tuple[str, ...]) -> None:
    """Refuse settings ``names`` of ``params`` that are not > 0 (ValueError)."""
    for name in names:
        value = check_number(params, name)
        if not value > 0:  # also refuses NaN; inf turns a limit off
            raise ValueError(f"{name} must be > 0, got {value}")


def check_lengths(params: Any, names: tuple[str, ...], off: str = "") -> None:
    """Refuse scale lengths ``names`` of ``params`` that are negative or NaN, or infinite
    unless ``off`` says what ``inf`` means (ValueError naming the setting). 0 is valid:
    derived from the reference when the servo is constructed (:mod:`spectral_vs.servo.scale`)."""
    for name in names:
        value = check_number(params, name)
        if not (value >= 0 and (off or math.isfinite(value))):
            meaning = f"0: derived from the reference{'; inf: ' + off if off else ''}"
            raise ValueError(
                f"{name} must be {'>= 0' if off else 'finite and >= 0'} m ({meaning}), got {value}"
            )


def check_at_least(params: Any, name: str, low: int, unit: str = "") -> None:
    """Refuse the setting ``name`` of ``params`` under ``low`` (ValueError)."""
    value = check_number(params, name)
    if not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {value!r}")
    if not int(value) >= low:
        raise ValueError(f"{name} must be >= {low}{' ' + unit if unit else ''}, got {value}")


def check_share(params: Any, names: tuple[str, ...]) -> None:
    """Refuse settings ``names`` of ``params`` outside [0, 1] (ValueError)."""
    for name in names:
        value = check_number(params, name)
        if not 0.0 <= value <= 1.0:
            raise ValueError(f"{name} must be in [0, 1], got {value}")


def check_keys(overrides: dict[str, Any], argument: str, settings: type) -> None:
    """Refuse keys of ``overrides`` that are no field of ``settings`` (TypeError naming the
    key, as the settings' own constructor does)."""
    for name in overrides:
        if name.startswith("_") or not hasattr(settings(), name):
            raise TypeError(f"{argument}: {settings.__name__} has no setting {name!r}")
