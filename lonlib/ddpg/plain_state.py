"""Checked reading of state stored as plain data: named tensors and JSON values.

An in-flight checkpoint (:mod:`lonlib.experiment.checkpoints`) stores a batch as tensors (loaded
with ``torch.load(..., weights_only=True)``, which builds no Python object but tensors and plain
containers) and JSON. Neither names a Python class, so reading one runs no code of the file's
choosing and survives moving or renaming modules. What comes back is still untrusted: these helpers
check every value's kind, shape and dtype against what the reader expects before anything uses it,
and raise :class:`StateLayoutError` naming the first that does not fit. The tensors read are
the file's CPU tensors, checked and converted on the host (``.numpy()``, ``bool``) directly;
only :meth:`TensorReader.take_like` puts one on a device, through
:func:`lonlib.ddpg.devices.to_device`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from lonlib.ddpg.devices import to_device
from lonlib.util.plain_data import (
    StateLayoutError,
)


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
        return to_device(self.take(name, tuple(like.shape), like.dtype, finite), like.device)

    def finish(self) -> None:
        """Refuse tensors nobody took (a layout this reader does not know)."""
        if self._tensors:
            raise StateLayoutError(f"{self._where}: unexpected tensors {sorted(self._tensors)}")
