"""Which CPU kernels an experiment computes with, and where that is recorded.

torch picks its vectorised CPU kernels (``torch.backends.cpu.get_cpu_capability()``) from
the CPU when it first runs one: AVX-512 where the CPU has it, else AVX2. The two round
differently, and DDPG's training is chaotic in the last bits (measured: the reference
experiment's first local search parts from its stored history at the first episode after
the warm-up under AVX-512; under AVX2 all 449 episodes, the fitness and every parameter are
identical). So lonlib pins torch to its AVX2 kernels on x86-64
(:func:`pin_torch_cpu_kernels`, called when ``lonlib`` is imported, before anything in it
imports torch; a value of ``ATEN_CPU_CAPABILITY`` already set wins; it has no effect once
torch has run a CPU kernel). Every x86-64 CPU with AVX2 then runs the same kernels. numpy's
own dispatch (AVX2 or AVX-512 loops) is recorded too; its AVX2 and AVX-512 loops gave
identical trials here, its SSE-only loops did not.

This module imports neither torch nor anything that does; :func:`torch_cpu_capability`
imports torch when called.
"""

from __future__ import annotations

import os
import platform
from collections.abc import MutableMapping
from typing import Any

CAPABILITY_VARIABLE = "ATEN_CPU_CAPABILITY"  # read by torch once, at its first CPU kernel
PINNED_CAPABILITY = "avx2"  # what lonlib sets (torch spells it "AVX2" when it reports it)


def is_x86_64() -> bool:
    """Whether this is an x86-64 machine (where torch has AVX2/AVX-512 kernels)."""
    return platform.machine().lower() in {"x86_64", "amd64"}


def pin_torch_cpu_kernels(environ: MutableMapping[str, str] = os.environ) -> None:
    """Default ``ATEN_CPU_CAPABILITY`` to ``avx2`` on x86-64 (child processes inherit it).
    Effective only before torch runs its first CPU kernel; a value already set is kept."""
    if is_x86_64():
        environ.setdefault(CAPABILITY_VARIABLE, PINNED_CAPABILITY)


def expected_torch_capability() -> str | None:
    """The capability torch reports when the pin took effect (None off x86-64, where
    lonlib pins nothing)."""
    return PINNED_CAPABILITY.upper() if is_x86_64() else None


def torch_cpu_capability() -> str:
    """torch's CPU capability in this process ("AVX2", "AVX512", "DEFAULT", ...); imports
    torch."""
    import torch

    return torch.backends.cpu.get_cpu_capability()


def numpy_cpu_features() -> dict[str, list[str]]:
    """numpy's SIMD build and what this CPU runs of it: ``baseline`` (compiled in),
    ``dispatch`` (the targets this CPU supports among those numpy can dispatch to)."""
    try:
        from numpy._core import _multiarray_umath as umath  # numpy >= 2
    except ImportError:  # pragma: no cover - numpy 1.x
        from numpy.core import _multiarray_umath as umath
    found = umath.__cpu_features__
    return {
        "baseline": list(umath.__cpu_baseline__),
        "dispatch": [name for name in umath.__cpu_dispatch__ if found.get(name)],
    }


def cpu_record(torch_capability: str | None) -> dict[str, Any]:
    """What the manifest records about the CPU kernels of a session: the machine, numpy's
    dispatch targets, torch's capability (``torch_capability``, None where torch was not
    asked) and the ``ATEN_CPU_CAPABILITY`` setting."""
    return {
        "machine": platform.machine(),
        "numpy": numpy_cpu_features(),
        "torch": torch_capability,
        CAPABILITY_VARIABLE: os.environ.get(CAPABILITY_VARIABLE),
    }


class CpuKernelWarning(UserWarning):
    """An experiment computes with other torch CPU kernels than lonlib pins, or than its
    earlier sessions did: its trials are not bit for bit those of other machines."""


def unpinned_message(torch_capability: str) -> str | None:
    """A message when torch runs other CPU kernels than lonlib pins (torch computed before
    lonlib was imported, ``ATEN_CPU_CAPABILITY`` was set to something else, or the CPU lacks
    AVX2); None when the pin holds."""
    expected = expected_torch_capability()
    if expected is None or torch_capability == expected:
        return None
    return (
        f"torch computes with its {torch_capability} CPU kernels here, not the {expected} "
        f"kernels lonlib pins ({CAPABILITY_VARIABLE}={os.environ.get(CAPABILITY_VARIABLE)!s}"
        "; torch reads it once, at its first CPU kernel): trials will not be bit for bit "
        "those of other machines. Import lonlib before using torch and leave "
        "ATEN_CPU_CAPABILITY unset (a CPU without AVX2 cannot run these kernels)"
    )
