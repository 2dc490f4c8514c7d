"""Progress bars that show where the user is looking.

A text bar on stderr everywhere (the terminal, and under papermill, whose runner
``lonlib.notebook_run`` copies the kernel's stderr to its terminal), except in a notebook
opened in JupyterLab with ipywidgets installed, where tqdm's widget is nicer. Never tqdm's
"IProgress not found" warning: the widget is used only when ipywidgets imports.
"""

from __future__ import annotations

import importlib.util
import os
import sys

from tqdm import tqdm


def in_jupyter_server_kernel() -> bool:
    """Whether this process is a kernel that a Jupyter server started for a notebook
    (jupyter_server sets ``JPY_SESSION_NAME``; papermill and the terminal do not)."""
    return "JPY_SESSION_NAME" in os.environ and "ipykernel" in sys.modules


def progress_bar(**options) -> tqdm:
    """A tqdm bar (``options`` as tqdm's): tqdm's notebook widget in a JupyterLab kernel
    with ipywidgets, a text line on stderr otherwise."""
    if in_jupyter_server_kernel() and importlib.util.find_spec("ipywidgets") is not None:
        from tqdm.notebook import tqdm as notebook_tqdm

        return notebook_tqdm(**options)
    return tqdm(file=sys.stderr, **options)
