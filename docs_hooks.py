"""MkDocs hook: the committed reference experiment's figures are part of the site (under
``reference-figures/``), read from ``data/reference/figures/`` at build time, so the docs
show the stored figures without a copy in ``docs/``."""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File, Files

FIGURES = Path(__file__).parent / "data" / "reference" / "figures"


def on_files(files: Files, config) -> Files:
    """Add every PNG of the reference experiment's figures to the site's files."""
    for path in sorted(FIGURES.glob("*.png")):
        files.append(
            File.generated(config, f"reference-figures/{path.name}", abs_src_path=str(path))
        )
    return files
