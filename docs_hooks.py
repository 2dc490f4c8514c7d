"""MkDocs hooks.

* The committed reference experiment's figures are part of the site (under
  ``reference-figures/``), read from ``data/reference/figures/`` at build time, and so are
  the one-cart LON's (``one-cart-figures/``, from ``data/one-cart/figures/``) and the
  two-cart study's (``study-figures/``, from ``data/studies/two-cart/``), so the docs show
  the stored figures without a copy in ``docs/``.
* The docstrings' Sphinx roles (``:class:`X```, ``:func:`~lonlib.a.f```, ...), which
  mkdocstrings renders as text, become code: a link to the object's API entry (through
  mkdocs-autorefs, silently unlinked where the site documents no such object) when the name
  is a dotted ``lonlib.`` path, plain code otherwise; ``~`` shows the last part only.
"""

from __future__ import annotations

import re
from pathlib import Path

from mkdocs.structure.files import File, Files

FIGURES = Path(__file__).parent / "data" / "reference" / "figures"
ONE_CART_FIGURES = Path(__file__).parent / "data" / "one-cart" / "figures"
STUDY_FIGURES = Path(__file__).parent / "data" / "studies" / "two-cart"

ROLE = re.compile(
    r":(?:class|func|meth|mod|data|attr|exc|obj|const|py:\w+):<code>(?P<target>[^<]+)</code>"
)


def on_files(files: Files, config) -> Files:
    """Add every PNG of the reference experiment's and the one-cart LON's figures and of the
    two-cart study to the site's files."""
    for folder, prefix in (
        (FIGURES, "reference-figures"),
        (ONE_CART_FIGURES, "one-cart-figures"),
        (STUDY_FIGURES, "study-figures"),
    ):
        for path in sorted(folder.glob("*.png")):
            files.append(File.generated(config, f"{prefix}/{path.name}", abs_src_path=str(path)))
    return files


def role_to_code(match: re.Match) -> str:
    """One Sphinx role as code, linked where it names a ``lonlib.`` object."""
    target = match["target"].strip()
    short = target.startswith("~")
    name = target.lstrip("~").lstrip(".")
    shown = name.rsplit(".", 1)[-1] if short else name
    if name.startswith("lonlib."):
        return f'<autoref identifier="{name}" optional><code>{shown}</code></autoref>'
    return f"<code>{shown}</code>"


def on_page_content(html: str, page, config, files) -> str:
    """Replace the Sphinx roles left in rendered docstrings (see the module docstring)."""
    return ROLE.sub(role_to_code, html)
