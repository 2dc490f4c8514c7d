"""Checked reading of state stored as plain data: named tensors and JSON values.

An in-flight checkpoint (:mod:`lonlib.experiment.checkpoints`) stores a batch as tensors (loaded
with
``torch.load(..., weights_only=True)``, which builds no Python object but tensors and plain
containers) and JSON. Neither names a Python class, so reading one runs no code of the
file's choosing and survives moving or renaming modules. What comes back is still untrusted:
these helpers check every value's kind, shape and dtype against what the reader expects
before anything uses it, and raise :class:`StateLayoutError` naming the first that does not
fit.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, TypeVar

import numpy as np
import torch

T = TypeVar("T")


class StateLayoutError(ValueError):
    """Stored state that does not have the layout its reader expects."""


class TensorReader:
    """Named tensors handed out one by one, each checked; :meth:`finish` refuses leftovers."""

    def __init__(self, tensors: Any, where: str = "tensors") -> None:
        if not isinstance(tensors, dict) or not all(isinstance(k, str) for k in tensors):
            raise StateLayoutError(f"{where}: not a mapping of names to tensors")
        self._tensors = dict(tensors)
        self._where = where

    def take(
        self, name: str, shape: tuple[int, ...], dtype: torch.dtype, finite: bool = False
    ) -> torch.Tensor:
        """The tensor ``name``, which must be a plain dense contiguous CPU tensor (not a
        ``Parameter`` nor requiring a gradient: in-place updates would fail) of ``shape``
        and ``dtype``, and with ``finite`` hold no NaN or infinite value."""
        if name not in self._tensors:
            raise StateLayoutError(f"{self._where}: tensor {name!r} is missing")
        value = self._tensors.pop(name)
        if not isinstance(value, torch.Tensor) or value.layout != torch.strided:
            raise StateLayoutError(f"{self._where}: {name!r} is not a dense tensor")
        if tuple(value.shape) != tuple(shape) or value.dtype != dtype:
            raise StateLayoutError(
                f"{self._where}: {name!r} is {value.dtype} {tuple(value.shape)}, "
                f"expected {dtype} {tuple(shape)}"
            )
        if (
            type(value) is not torch.Tensor
            or value.requires_grad
            or not value.is_contiguous()
            or value.device.type != "cpu"
        ):
            raise StateLayoutError(
                f"{self._where}: {name!r} is not a plain tensor (a Parameter or another "
                "kind, requiring a gradient, not contiguous or not on the CPU)"
            )
        if finite and dtype.is_floating_point and not bool(torch.isfinite(value).all()):
            raise StateLayoutError(f"{self._where}: {name!r} holds NaN or infinite values")
        return value

    def take_numpy(
        self, name: str, shape: tuple[int, ...], dtype: torch.dtype, finite: bool = False
    ) -> np.ndarray:
        """:meth:`take` as a numpy array of its own (not sharing the tensor's memory)."""
        return self.take(name, shape, dtype, finite).numpy().copy()

    def take_like(self, name: str, like: np.ndarray | torch.Tensor, finite: bool = False) -> Any:
        """The tensor ``name`` with ``like``'s shape and dtype, as ``like``'s kind: a numpy
        array of its own, or a tensor of its own on ``like``'s device."""
        if isinstance(like, np.ndarray):
            dtype = torch.from_numpy(np.empty(0, like.dtype)).dtype
            return self.take_numpy(name, like.shape, dtype, finite)
        return self.take(name, tuple(like.shape), like.dtype, finite).to(like.device, copy=True)

    def finish(self) -> None:
        """Refuse tensors nobody took (a layout this reader does not know)."""
        if self._tensors:
            raise StateLayoutError(f"{self._where}: unexpected tensors {sorted(self._tensors)}")


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


def config_from_plain(cls: type[T], value: Any, name: str) -> T:
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
