"""``python -m lonlib.notebook_run``: papermill's command line, as ``make reproduce`` uses it.

The same arguments as ``papermill`` with two differences in how the kernel runs:

* its connection is encrypted (CurveZMQ keys provisioned by jupyter_client, which the
  standard ``python3`` kernelspec declares it supports), so the kernel does not warn
  "Kernel is running over TCP without encryption" in the terminal;
* its stderr (progress bars, warnings) is copied to this process's stderr as it arrives,
  so a long sampling notebook shows its progress in the terminal (``--stderr-file`` still
  chooses another file).
"""

from __future__ import annotations

import sys

from papermill.engines import NBClientEngine, papermill_engines
from traitlets.config import Config


class TerminalEngine(NBClientEngine):
    """papermill's nbclient engine with an encrypted kernel connection and the kernel's
    stderr streamed to the terminal."""

    @classmethod
    def execute_managed_notebook(cls, nb_man, kernel_name, **kwargs):
        """Run the notebook as :class:`NBClientEngine` does, with this engine's defaults."""
        if kwargs.get("stderr_file") is None:
            kwargs["stderr_file"] = sys.stderr
        config = kwargs.pop("config", None) or Config()
        config.KernelManager.transport_encryption = "auto"
        return super().execute_managed_notebook(nb_man, kernel_name, config=config, **kwargs)


def main() -> None:
    """Run papermill's command line with :class:`TerminalEngine` as the default engine."""
    from papermill.cli import papermill

    papermill_engines.register(None, TerminalEngine)
    papermill_engines.register("lonlib", TerminalEngine)
    papermill(prog_name="papermill")


if __name__ == "__main__":
    main()
