"""Which rollout runs: the numba-compiled kernels or the numpy definition (same bits).

The one rollout (:mod:`lonlib.task.rollout`) and the simulator's batched ``step`` and
``observe`` run on the compiled kernels of :mod:`lonlib.task.kernels` when numba is
installed and they compile; otherwise on their numpy definition, which stays the oracle the
tests compare the kernels with. Both give the same bits (docs/rollout.md says why).

* ``LONLIB_ROLLOUT=numpy`` forces the numpy definition; ``LONLIB_ROLLOUT=numba`` requires
  the kernels (an error, not a fallback, when they cannot be loaded); unset: the kernels
  when they load, else numpy with one warning.
* numba is imported on first use only, so ``import lonlib``, ``lonlib status`` and
  ``import lonlib.analysis`` pay nothing for it.
* Compiled code is cached in :func:`cache_folder`: ``$LONLIB_CACHE_DIR`` (default
  ``$XDG_CACHE_HOME/lonlib`` or ``~/.cache/lonlib``) ``/numba/<lonlib version>-<hash of the
  kernel sources>``, because numba's own invalidation follows only the decorated file's time
  stamp (an edited callee in another file would stay stale). No writable folder: the kernels
  compile without a cache (about 20 s per process here), never an import error.
* Intel SVML is switched off (``NUMBA_DISABLE_INTEL_SVML``) before numba is imported.

The configuration reaches the kernels as two small arrays (:func:`pack`), so one compilation
serves every configuration, number of carts and batch.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import os
import tempfile
import threading
import warnings
from pathlib import Path
from types import ModuleType

from lonlib.task.kernel_config import pack  # noqa: F401 (the public way in)
from lonlib.util import portable_math

ROLLOUT_VARIABLE = "LONLIB_ROLLOUT"
CACHE_VARIABLE = "LONLIB_CACHE_DIR"
ROLLOUTS = ("numba", "numpy")

# The sources whose text the compiled code depends on (the cache key).
_SOURCES = ("kernels.py", "kernel_config.py")

_lock = threading.Lock()
_loaded: dict[str, ModuleType | None] = {}
_threads = {"count": 1}


def requested() -> str | None:
    """``LONLIB_ROLLOUT`` as set (``numba``, ``numpy``) or None; another value is an error
    that names the variable and its allowed values."""
    value = os.environ.get(ROLLOUT_VARIABLE, "").strip().lower()
    if not value:
        return None
    if value not in ROLLOUTS:
        raise ValueError(
            f"{ROLLOUT_VARIABLE} must be one of {list(ROLLOUTS)} or unset, got {value!r}"
        )
    return value


def source_hash() -> str:
    """A hash of the kernel sources and of the portable math they port (the cache key)."""
    digest = hashlib.sha256()
    here = Path(__file__).parent
    for path in [*(here / name for name in _SOURCES), Path(portable_math.__file__)]:
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def package_version() -> str:
    """lonlib's installed version (``unknown`` when it runs from a source tree only)."""
    try:
        return importlib.metadata.version("lonlib")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def cache_folder() -> Path | None:
    """The writable folder compiled kernels are cached in, made if needed; None when there
    is none (the kernels then compile in every process, without a cache)."""
    base = os.environ.get(CACHE_VARIABLE) or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"),
        "lonlib",
    )
    folder = Path(base) / "numba" / f"{package_version()}-{source_hash()}"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder):
            pass
    except OSError:
        return None
    return folder


def kernels() -> ModuleType | None:
    """The compiled kernels' module, or None when the numpy definition runs (forced by
    ``LONLIB_ROLLOUT=numpy``, or numba missing or failing: one warning)."""
    choice = requested()
    if choice == "numpy":
        return None
    with _lock:
        if "kernels" not in _loaded:
            _loaded["kernels"] = _load(required=choice == "numba")
    return _loaded["kernels"]


def _load(required: bool) -> ModuleType | None:
    os.environ.setdefault("NUMBA_DISABLE_INTEL_SVML", "1")
    try:
        import numba

        numba.config.DISABLE_INTEL_SVML = True
        folder = cache_folder()
        if folder is not None:
            numba.config.CACHE_DIR = str(folder)
        from lonlib.task import kernels as module

        numba.set_num_threads(_threads["count"])  # 1 unless set_threads spread rows wider
        module.warm_up()
        return module
    except Exception as error:  # numba missing, or a kernel failing to compile
        if required:
            raise RuntimeError(
                f"{ROLLOUT_VARIABLE}=numba, but the compiled rollout cannot be loaded: {error}"
            ) from error
        warnings.warn(
            f"lonlib runs the numpy rollout (same bits, ~100x slower): the compiled one "
            f"cannot be loaded ({type(error).__name__}: {error})",
            RuntimeWarning,
            stacklevel=3,
        )
        return None


def backend() -> str:
    """``numba`` or ``numpy``: what the one rollout runs on in this process."""
    return "numpy" if kernels() is None else "numba"


def set_threads(threads: int) -> int:
    """Spread a batched rollout's rows over ``threads`` threads (numba's ``prange``; at most
    numba's thread count), in every thread of this process that runs a rollout from now on;
    returns the count set. Default 1, so that processes running side by side (a pool, Dask
    workers, torch's own threads) are never oversubscribed."""
    module = kernels()
    if module is None:
        return 1
    import numba

    _threads["count"] = max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(_threads["count"])
    return _threads["count"]


def apply_threads() -> None:
    """Give the calling thread the count of :func:`set_threads` (numba's count is per
    thread: a rollout started from another thread, e.g. a Dask worker's, would otherwise use
    every core)."""
    import numba

    if numba.get_num_threads() != _threads["count"]:
        numba.set_num_threads(_threads["count"])
