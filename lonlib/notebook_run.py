"""``python -m lonlib.notebook_run``: papermill's command line, as ``make reproduce`` uses it.

The same arguments as ``papermill`` with two differences in how the kernel runs:

* its connection is encrypted (CurveZMQ keys provisioned by jupyter_client), so ipykernel
  (7.3 and later) does not warn "Kernel is running over TCP without encryption" in the
  terminal. jupyter_client provisions keys (``transport_encryption = "auto"``) only when the
  kernelspec *file* it finds declares ``supported_encryption``; a ``python3`` kernelspec
  written by an older ipykernel (in ``~/.local/share/jupyter``, on ``JUPYTER_PATH``, in a
  conda environment) does not, although the kernel that runs is this interpreter's ipykernel.
  :class:`EncryptedKernelManager` therefore asks that ipykernel instead of the file;
* its stderr (progress bars, warnings) is copied to this process's stderr as it arrives,
  so a long sampling notebook shows its progress in the terminal (``--stderr-file`` still
  chooses another file).

The engine is also registered with papermill as ``lonlib`` (an entry point), so
``papermill.execute_notebook(..., engine_name="lonlib")`` runs notebooks the same way.
papermill loads its entry points while ``papermill.engines`` is being imported, so this module
imports papermill only when :class:`TerminalEngine` is first asked for (a module
``__getattr__``): importing it first, or papermill first, both work.
"""

from __future__ import annotations

import sys
from typing import Any

import zmq
from jupyter_client import AsyncKernelManager, KernelManager
from jupyter_client.kernelspec import KernelSpec
from traitlets.config import Config


def declares_curve(metadata: dict[str, Any] | None) -> bool:
    """Whether kernelspec ``metadata`` declares CurveZMQ support (a string or a list, as
    ipykernel 7.3 and 7.4 write it)."""
    declared = (metadata or {}).get("supported_encryption")
    if isinstance(declared, str):
        return declared.strip().lower() == "curve"
    if isinstance(declared, (list, tuple, set)):
        return "curve" in {str(item).strip().lower() for item in declared}
    return False


def runs_this_ipykernel(argv: list[str]) -> bool:
    """Whether a kernelspec's command starts this interpreter's ipykernel (jupyter_client
    runs ``python``, ``python3`` and ``python3.X`` as ``sys.executable``)."""
    major, minor = sys.version_info[:2]
    pythons = {"python", f"python{major}", f"python{major}.{minor}"}
    if not argv or argv[0] not in {*pythons, sys.executable}:
        return False
    return any(
        flag == "-m" and module in {"ipykernel", "ipykernel_launcher"}
        for flag, module in zip(argv, argv[1:], strict=False)
    )


def this_ipykernel_supports_curve() -> bool:
    """Whether the ipykernel installed here accepts manager-provisioned CurveZMQ keys (it
    says so in the kernelspec it writes) and pyzmq can encrypt."""
    try:
        from ipykernel.kernelspec import get_kernel_dict
    except ImportError:
        return False
    return zmq.has("curve") and declares_curve(get_kernel_dict().get("metadata"))


class EncryptedKernelManager(AsyncKernelManager):
    """nbclient's kernel manager, whose kernelspec declares CurveZMQ support whenever the
    kernel it starts is this interpreter's ipykernel and that ipykernel supports it,
    whatever kernelspec file jupyter_client found."""

    @property
    def kernel_spec(self) -> KernelSpec | None:
        """The kernelspec jupyter_client found, with ``supported_encryption`` added when
        the kernel is this interpreter's curve-capable ipykernel."""
        spec = super().kernel_spec
        if (
            spec is not None
            and not declares_curve(spec.metadata)
            and runs_this_ipykernel(list(spec.argv))
            and this_ipykernel_supports_curve()
        ):
            spec.metadata = {**spec.metadata, "supported_encryption": ["curve"]}
        return spec


def encrypted_kernel_config(config: Config | None = None) -> Config:
    """``config`` (or a new one) with the kernel connection encrypted where this
    jupyter_client and pyzmq can do it; unchanged settings otherwise."""
    config = config or Config()
    if "transport_encryption" in KernelManager.class_trait_names() and zmq.has("curve"):
        config.KernelManager.transport_encryption = "auto"
        config.NotebookClient.kernel_manager_class = EncryptedKernelManager
    return config


def _terminal_engine() -> type:
    """papermill's nbclient engine with an encrypted kernel connection and the kernel's
    stderr streamed to the terminal (built once, on first use)."""
    from papermill.engines import NBClientEngine  # defined before papermill loads entry points

    class TerminalEngine(NBClientEngine):
        """papermill's nbclient engine with an encrypted kernel connection and the kernel's
        stderr streamed to the terminal."""

        @classmethod
        def execute_managed_notebook(cls, nb_man, kernel_name, **kwargs):
            """Run the notebook as :class:`NBClientEngine` does, with this engine's defaults."""
            if kwargs.get("stderr_file") is None:
                kwargs["stderr_file"] = sys.stderr
            config = encrypted_kernel_config(kwargs.pop("config", None))
            return super().execute_managed_notebook(nb_man, kernel_name, config=config, **kwargs)

    TerminalEngine.__module__ = __name__
    TerminalEngine.__qualname__ = "TerminalEngine"
    return TerminalEngine


def __getattr__(name: str) -> Any:
    """``TerminalEngine``, built on first access (see the module docstring)."""
    if name != "TerminalEngine":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    engine = _terminal_engine()
    # papermill's first import asks for the engine again (its entry point) before this call
    # returns: the class that papermill registered is the one kept.
    return globals().setdefault("TerminalEngine", engine)


def main() -> None:
    """Run papermill's command line with :class:`TerminalEngine` as the default engine."""
    from papermill.cli import papermill
    from papermill.engines import papermill_engines

    engine = __getattr__("TerminalEngine")
    papermill_engines.register(None, engine)
    papermill_engines.register("lonlib", engine)
    papermill(prog_name="papermill")


if __name__ == "__main__":
    main()
