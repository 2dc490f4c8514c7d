"""`python -m benchmarks.readme`: paste the generated speed tables into docs/performance.md.

`make bench` writes ``benchmarks/results/ddpg.md`` and ``lockstep.md``; this replaces the
page's lines between the ``ddpg-speed`` and ``lockstep-speed`` markers with them, so the
tables are never typed by hand. A table whose result file is missing is left as it is.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.common import RESULTS
from lonlib.util.readme_tables import splice as splice_between

README = Path(__file__).parents[1] / "docs" / "performance.md"
BEGIN, END = "<!-- ddpg-speed:begin (python -m benchmarks.readme) -->", "<!-- ddpg-speed:end -->"
TABLES = {
    "ddpg.md": (BEGIN, END),
    "lockstep.md": (
        "<!-- lockstep-speed:begin (python -m benchmarks.readme) -->",
        "<!-- lockstep-speed:end -->",
    ),
}


def splice(readme: str, table: str) -> str:
    """``readme`` with the text between the DDPG markers replaced by ``table``."""
    return splice_between(readme, BEGIN, END, table)


def main() -> None:
    """Rewrite docs/performance.md's speed tables from ``benchmarks/results/``."""
    readme = README.read_text()
    for name, (begin, end) in TABLES.items():
        if (RESULTS / name).exists():
            readme = splice_between(readme, begin, end, (RESULTS / name).read_text())
            print(f"{README}: table replaced from {RESULTS / name}")
    README.write_text(readme)


if __name__ == "__main__":
    main()
