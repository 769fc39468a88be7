"""Checks of settings where they are made: one :class:`InputError` line that names the setting.

Every frozen configuration of corl (``CORLConfig``, ``RegressionConfig``, ``ClassifierConfig``,
``MethodSettings``, ...) checks its fields in ``__post_init__`` with these helpers, so a wrong type,
a NaN or a value out of range is refused when the setting is written, before any rollout. A
setting's name is given as ``Owner.field`` so the message says where to look.

:func:`keywords` guards a configuration's constructor: an unknown keyword (a typo) or a removed
one answers with a one-line InputError naming the valid fields or the new home, instead of
dataclass's raw ``TypeError``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
from typing import Any, Mapping

import numpy as np

from corl.errors import InputError

__all__ = ["number", "integer", "flag", "text", "function", "lengths", "keywords"]


def _is_real(value: Any) -> bool:
    return isinstance(value, (numbers.Real, np.floating, np.integer)) and not isinstance(value, (bool, np.bool_))


def number(name: str, value: Any, *, low: float = -math.inf, high: float = math.inf, low_open: bool = False,
           high_open: bool = False, finite: bool = True) -> float:
    """``value`` as a float: a real number (not a bool or a string), not NaN, finite unless
    ``finite=False``, within ``[low, high]`` (an end left out with ``low_open`` / ``high_open``)."""
    if not _is_real(value):
        raise InputError(f"{name} must be a number, got {value!r}")
    v = float(value)
    if math.isnan(v) or (finite and math.isinf(v)):
        raise InputError(f"{name} must be a finite number, got {value!r}")
    if v < low or v > high or (low_open and v == low) or (high_open and v == high):
        lo = "(" if low_open else "["
        hi = f"{high:g}" + (")" if high_open else "]") if math.isfinite(high) else "inf)"
        raise InputError(f"{name} must be in {lo}{low:g}, {hi}, got {value!r}")
    return v


def integer(name: str, value: Any, *, low: int = 0, high: int | None = None) -> int:
    """``value`` as an int: an integer (``3`` or ``3.0``; not ``2.5``, a bool or a string) ``>= low``
    (and ``<= high`` when given)."""
    if not _is_real(value) or not math.isfinite(float(value)) or float(value) != int(value):
        raise InputError(f"{name} must be a whole number, got {value!r}")
    v = int(value)
    if v < low or (high is not None and v > high):
        bound = f">= {low}" if high is None else f"in {low}..{high}"
        raise InputError(f"{name} must be an integer {bound}, got {value!r}")
    return v


def flag(name: str, value: Any) -> bool:
    """``value`` as a bool: ``True`` or ``False`` only (not 0, 1 or ``"yes"``)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def text(name: str, value: Any, *, spaces: bool = True, ascii: bool = False, secret: bool = False) -> str:
    """``value`` as a str on one line: not empty, printable characters only (no CR, LF or other control
    characters), without whitespace unless ``spaces``, ASCII only with ``ascii``. A ``secret`` (a token)
    is not repeated in the message."""
    good = isinstance(value, str) and value and value.isprintable() and (spaces or not any(c.isspace() for c in value)) \
        and (value.isascii() or not ascii)
    if not good:
        what = "one line of printable" + (" ASCII" if ascii else "") + " characters" + ("" if spaces else " without spaces")
        got = f"a {type(value).__name__}" if secret or not isinstance(value, str) else repr(value)
        raise InputError(f"{name} must be {what}, got {got[:80]}")
    return value


def function(name: str, value: Any, *, what: str, optional: bool = True) -> Any:
    """``value`` when it is callable (or None, when ``optional``); ``what`` says what it is called with."""
    if (value is None and optional) or callable(value):
        return value
    alternative = " or None" if optional else ""
    raise InputError(f"{name} must be a function {what}{alternative}, got {type(value).__name__} {value!r:.40}")


def lengths(name: str, value: Any, *, low: float = 0.0) -> float | tuple[float, ...]:
    """A length scale: one positive finite number, or a non-empty sequence of them (one per
    dimension of theta, ARD). Returned as a float or a tuple of floats."""
    if _is_real(value):
        return number(name, value, low=low, low_open=True)
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        raise InputError(f"{name} must be a positive number or a sequence of them (one per dimension of theta), "
                         f"got {value!r}")
    items = tuple(np.ravel(np.asarray(value, dtype=object)))
    if not items:
        raise InputError(f"{name} must not be empty: give one value per dimension of theta")
    return tuple(number(f"{name}[{i}]", v, low=low, low_open=True) for i, v in enumerate(items))


def keywords(removed: Mapping[str, str] | None = None):
    """Class decorator for a configuration dataclass: unknown or removed keywords of its constructor
    raise a one-line :class:`InputError` (``removed`` maps an old name to where it went)."""
    removed = dict(removed or {})

    def wrap(cls):
        init = cls.__init__
        names = [f.name for f in dataclasses.fields(cls) if f.init]

        @functools.wraps(init)
        def __init__(self, *args, **kwargs):
            for key in kwargs:
                if key in removed:
                    raise InputError(f"{cls.__name__}({key}=...) was removed: {removed[key]}")
                if key not in names:
                    raise InputError(f"{cls.__name__} has no setting {key!r}; its settings are {', '.join(names)}")
            if len(args) > len(names):
                raise InputError(f"{cls.__name__} takes at most {len(names)} settings, got {len(args)} positional")
            init(self, *args, **kwargs)

        cls.__init__ = __init__
        return cls

    return wrap
