"""Every copy between the host (numpy) and DDPG's torch device, counted, and the one
test-only switch that makes the CPU behave as a device.

The lockstep step keeps its state on the learner's device: replay rows, positions and fill
levels, the slots' step counters and busy mask, stream keys, replay indices, Adam step
counts and coefficients, loss sums. Per environment step only two copies cross
(:class:`TransferLog` counts them; ``tests/ddpg/test_devices.py`` asserts it): the environment's
outputs (rewards, next observations, ends) go to the device, and the actions come back.
Everything else crosses at events, and only what the event's slots need: at an episode end
those slots' indices go and their parameters and loss sums come back (the greedy evaluation
runs on the host), then the reset observations go; a search's start sends its parameters,
the stream keys and its slot's index; the step after any start, stop, drop, shrink or
restore sends the step counters and busy mask once; a checkpoint brings every device tensor
back once and a restore sends it again.

Host data are numpy arrays and device data torch tensors, and every conversion between the
two in the step goes through :func:`to_device`, :func:`copy_to_device` and
:func:`to_host`, which always copy (on the CPU too: a caller never aliases memory on one
device and not on another; the one exception, a ``temporary`` made for the copy, is
documented there). The CPU is the host's own memory, which one branch uses for speed: the
counter-based streams hash with numpy there (:mod:`lonlib.ddpg.streams`) and see CPU
tensors through :func:`host_view` and :func:`host_tensor` without a copy. That branch asks
:func:`is_host`, and under :func:`cpu_as_device` (tests only) :func:`is_host` says no for
the CPU too, so that the CPU takes every path a CUDA device takes; results are bit for bit
the same either way (tested).

Scope: the lockstep step, which needs the lean learner (:mod:`lonlib.ddpg.lean`). There
:func:`is_host` is the only condition on the device and this module makes every copy. Code
outside it decides or copies by itself: the autograd reference learner
(:mod:`lonlib.ddpg.reference`: fused Adam by device type, its losses and parameters copied
with ``.cpu()`` and ``torch.as_tensor``), :class:`lonlib.ddpg.nets.BatchedMLP`,
:func:`lonlib.ddpg.trainer.check_device` (which devices exist) and the checkpoint reader
(:mod:`lonlib.ddpg.plain_state`, which checks and converts the CPU tensors of a file).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
import torch

_CPU_AS_DEVICE = False  # set only by cpu_as_device() (tests)
_LOGS: list[TransferLog] = []  # the active logs, innermost last


def is_host(device: str | torch.device) -> bool:
    """Whether tensors on ``device`` live in host memory, so that numpy may read and write
    them in place (the CPU; not under :func:`cpu_as_device`)."""
    return torch.device(device).type == "cpu" and not _CPU_AS_DEVICE


@contextmanager
def cpu_as_device() -> Iterator[None]:
    """Test only: while active, the CPU is a device (:func:`is_host` is false): objects
    made take the branches a CUDA device takes, and :func:`host_view` refuses CPU tensors
    as it refuses CUDA ones. Make and use the objects inside it (an object keeps the path
    chosen when it was made). Not thread-safe; not inherited by other processes."""
    global _CPU_AS_DEVICE
    before, _CPU_AS_DEVICE = _CPU_AS_DEVICE, True
    try:
        yield
    finally:
        _CPU_AS_DEVICE = before


@dataclass(frozen=True)
class Transfer:
    """One copy between host and device: ``"to device"`` or ``"to host"``, with the copied
    values' shape and dtype."""

    direction: str
    shape: tuple[int, ...]
    dtype: torch.dtype


@dataclass
class TransferLog:
    """Records every copy :func:`to_device`, :func:`copy_to_device` and :func:`to_host`
    make while it is active (``with TransferLog() as log: ...``; logs nest, each records)."""

    transfers: list[Transfer] = field(default_factory=list)

    def __enter__(self) -> TransferLog:
        _LOGS.append(self)
        return self

    def __exit__(self, *exc: object) -> None:
        _LOGS.remove(self)

    def clear(self) -> None:
        """Forget what was recorded so far."""
        self.transfers.clear()

    def count(self, direction: str) -> int:
        """How many copies went ``direction`` (``"to device"`` or ``"to host"``)."""
        return sum(t.direction == direction for t in self.transfers)


def _record(direction: str, tensor: torch.Tensor) -> None:
    for log in _LOGS:
        log.transfers.append(Transfer(direction, tuple(tensor.shape), tensor.dtype))


def to_device(
    values: np.ndarray | torch.Tensor | list | int | float,
    device: str | torch.device,
    dtype: torch.dtype | None = None,
) -> torch.Tensor:
    """A copy of host ``values`` (a numpy array, numbers, or a CPU tensor) on ``device``
    (as ``dtype`` if given; numpy's dtype otherwise). One counted copy."""
    if isinstance(values, torch.Tensor):
        out = values.to(device=device, dtype=dtype, copy=True)
    else:
        out = torch.tensor(np.asarray(values), dtype=dtype, device=device)
    _record("to device", out)
    return out


def copy_to_device(values: np.ndarray | torch.Tensor, out: torch.Tensor) -> torch.Tensor:
    """Write host ``values`` (a numpy array or a CPU tensor) into the device tensor ``out``
    (cast to its dtype; no new device memory); returns ``out``. One counted copy."""
    if not isinstance(values, torch.Tensor):
        values = torch.from_numpy(np.ascontiguousarray(values))
    elif values.device.type != "cpu":
        raise ValueError(f"copy_to_device copies host values, got a tensor on {values.device}")
    out.copy_(values)
    _record("to device", out)
    return out


def to_host(tensor: torch.Tensor, temporary: bool = False) -> np.ndarray:
    """The values of a device tensor as a numpy array of their own (never sharing the
    tensor's memory, on the CPU neither). One counted copy.

    ``temporary``: the caller made ``tensor`` for this copy alone (a fresh result, no view,
    held by nothing else), so in host memory (:func:`is_host`) the array takes its memory
    over instead of copying it: a large export (a checkpoint's replay rows) then holds its
    values once, not twice. Elsewhere it is copied as always."""
    _record("to host", tensor)
    if temporary and is_host(tensor.device):
        return tensor.detach().numpy()
    return tensor.detach().to("cpu", copy=True).numpy()


def on_device(tensor: torch.Tensor, device: str | torch.device) -> bool:
    """Whether ``tensor`` lives on ``device`` (a device without an index, such as
    ``"cuda"``, stands for any of its kind)."""
    device = torch.device(device)
    return tensor.device.type == device.type and (
        device.index is None or tensor.device.index == device.index
    )


def host_view(tensor: torch.Tensor) -> np.ndarray:
    """A numpy view of a tensor in host memory (:func:`is_host`): no copy, and not a
    transfer (for the code that :func:`is_host` lets compute with numpy)."""
    if not is_host(tensor.device):
        raise ValueError(f"a numpy view needs a tensor in host memory, got one on {tensor.device}")
    return tensor.numpy()


def host_tensor(values: np.ndarray) -> torch.Tensor:
    """A CPU tensor over a numpy array's memory: no copy, and not a transfer (the
    counterpart of :func:`host_view`)."""
    return torch.from_numpy(values)
