"""Checked reading of JSON values stored as plain data (no torch).

Stored state (an in-flight checkpoint's metadata and settings, :mod:`lonlib.storage.inflight`)
is untrusted: these helpers check every value's kind and range against what the reader
expects before anything uses it, and raise :class:`StateLayoutError` naming the first that does
not fit. The tensors beside them are read by :mod:`lonlib.ddpg.plain_state`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, TypeVar

import numpy as np

_T = TypeVar("_T")


class StateLayoutError(ValueError):
    """Stored state that does not have the layout its reader expects."""


def plain_int(value: Any, name: str, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an integer (not a bool) in ``[low, high]``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise StateLayoutError(f"{name} must be an integer, got {short_repr(value)}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise StateLayoutError(f"{name} must be in [{low}, {high}], got {short_repr(value)}")
    return value


def plain_float(value: Any, name: str, finite: bool = False) -> float:
    """``value`` as a float (JSON numbers, ``NaN`` and ``Infinity`` included unless
    ``finite``; not a bool, nor an integer too large for a float)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise StateLayoutError(f"{name} must be a number, got {short_repr(value)}")
    try:
        number = float(value)
    except OverflowError:
        raise StateLayoutError(f"{name} is too large for a float") from None
    if finite and not math.isfinite(number):
        raise StateLayoutError(f"{name} must be finite, got {number}")
    return number


def short_repr(value: Any) -> str:
    """``repr(value)`` cut short, for messages: a hostile file's values can be huge (an
    integer of thousands of digits has no ``repr``)."""
    try:
        text = repr(value)
    except ValueError:
        return f"{type(value).__name__} too large to show"
    return text if len(text) <= 80 else f"{text[:77]}..."


def plain_bool(value: Any, name: str) -> bool:
    """``value``, which must be a bool."""
    if not isinstance(value, bool):
        raise StateLayoutError(f"{name} must be true or false, got {short_repr(value)}")
    return value


def plain_str(value: Any, name: str) -> str:
    """``value``, which must be text."""
    if not isinstance(value, str):
        raise StateLayoutError(f"{name} must be text, got {short_repr(value)}")
    return value


def plain_list(value: Any, name: str, length: int | None = None) -> list:
    """``value``, which must be a list (of ``length`` items if given)."""
    if not isinstance(value, list):
        raise StateLayoutError(f"{name} must be a list, got {type(value).__name__}")
    if length is not None and len(value) != length:
        raise StateLayoutError(f"{name} must have {length} items, got {len(value)}")
    return value


def plain_dict(value: Any, name: str, keys: set[str] | frozenset[str]) -> dict[str, Any]:
    """``value``, which must be a mapping with exactly ``keys``."""
    if not isinstance(value, dict):
        raise StateLayoutError(f"{name} must be a mapping, got {type(value).__name__}")
    if set(value) != set(keys):
        missing, extra = sorted(set(keys) - set(value)), sorted(set(value) - set(keys))
        raise StateLayoutError(f"{name}: missing keys {missing}, unexpected keys {extra}")
    return value


def config_from_plain(cls: type[_T], value: Any, name: str) -> _T:
    """The frozen configuration dataclass ``cls`` from its fields as plain data
    (:func:`dataclasses.asdict`), every field present and valid."""
    values = plain_dict(value, name, {f.name for f in dataclasses.fields(cls)})
    try:
        return cls(**values)
    except (TypeError, ValueError, OverflowError) as error:
        raise StateLayoutError(f"{name}: {error}") from None


def generator_state(generator: np.random.Generator) -> dict[str, Any]:
    """A numpy generator's state as plain (JSON-able) data."""
    return generator.bit_generator.state


def generator_from_state(state: Any, name: str) -> np.random.Generator:
    """A PCG64 numpy generator continuing from :func:`generator_state`'s ``state``."""
    if not isinstance(state, dict) or state.get("bit_generator") != "PCG64":
        raise StateLayoutError(f"{name} must be the state of a PCG64 generator")
    bit_generator = np.random.PCG64()
    try:
        bit_generator.state = state
    except (TypeError, ValueError, KeyError, OverflowError) as error:
        raise StateLayoutError(f"{name}: {error}") from None
    return np.random.Generator(bit_generator)
