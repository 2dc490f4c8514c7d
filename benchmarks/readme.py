"""`python -m benchmarks.readme`: paste the generated DDPG speed table into README.md.

`make bench` writes ``benchmarks/results/ddpg.md``; this replaces the README's lines between
the ``ddpg-speed`` markers with it, so the table is never typed by hand.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.common import RESULTS
from lonlib.readme_tables import splice as splice_between

README = Path(__file__).parents[1] / "README.md"
BEGIN, END = "<!-- ddpg-speed:begin (python -m benchmarks.readme) -->", "<!-- ddpg-speed:end -->"


def splice(readme: str, table: str) -> str:
    """``readme`` with the text between the markers replaced by ``table``."""
    return splice_between(readme, BEGIN, END, table)


def main() -> None:
    """Rewrite README.md's DDPG speed table from ``benchmarks/results/ddpg.md``."""
    table = (RESULTS / "ddpg.md").read_text()
    README.write_text(splice(README.read_text(), table))
    print(f"README.md: DDPG speed table replaced from {RESULTS / 'ddpg.md'}")


if __name__ == "__main__":
    main()
