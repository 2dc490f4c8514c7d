"""`python -m benchmarks.readme`: paste the generated DDPG speed table into README.md.

`make bench` writes ``benchmarks/results/ddpg.md``; this replaces the README's lines between
the ``ddpg-speed`` markers with it, so the table is never typed by hand.
"""

from __future__ import annotations

from pathlib import Path

from benchmarks.common import RESULTS

README = Path(__file__).parents[1] / "README.md"
BEGIN, END = "<!-- ddpg-speed:begin (python -m benchmarks.readme) -->", "<!-- ddpg-speed:end -->"


def splice(readme: str, table: str) -> str:
    """``readme`` with the text between the markers replaced by ``table``."""
    if readme.count(BEGIN) != 1 or readme.count(END) != 1:
        raise ValueError(f"README.md must hold the markers {BEGIN!r} and {END!r} once each")
    head, rest = readme.split(BEGIN)
    _, tail = rest.split(END)
    return f"{head}{BEGIN}\n{table.strip()}\n{END}{tail}"


def main() -> None:
    """Rewrite README.md's DDPG speed table from ``benchmarks/results/ddpg.md``."""
    table = (RESULTS / "ddpg.md").read_text()
    README.write_text(splice(README.read_text(), table))
    print(f"README.md: DDPG speed table replaced from {RESULTS / 'ddpg.md'}")


if __name__ == "__main__":
    main()
