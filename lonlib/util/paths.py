"""Where the project's ``data/`` is, whatever the working directory.

JupyterLab starts a notebook's kernel in the notebook's folder (``notebooks/``); papermill
and ``make`` run from the repository root. Notebook parameters such as ``data/quick`` mean
the same folder in both: :func:`project_path` reads a relative path from the project root,
the nearest folder (the working directory or one of its parents) that holds ``data/``
beside ``pyproject.toml``.
"""

from __future__ import annotations

from pathlib import Path


def project_root(start: str | Path | None = None) -> Path:
    """The nearest of ``start`` (default: the working directory) and its parents holding both
    ``pyproject.toml`` and a ``data/`` folder; ``start`` itself when none does."""
    here = Path.cwd() if start is None else Path(start)
    here = here.resolve()
    for folder in (here, *here.parents):
        if (folder / "pyproject.toml").is_file() and (folder / "data").is_dir():
            return folder
    return here


def project_path(path: str | Path, start: str | Path | None = None) -> Path:
    """``path`` as the notebooks mean it: an absolute path as it is, a relative one under
    :func:`project_root` (so ``data/quick`` is one folder from ``notebooks/`` and from the
    repository root)."""
    path = Path(path).expanduser()
    return path if path.is_absolute() else project_root(start) / path
