"""Generated tables in Markdown files: the text between a pair of marker comments is
replaced by a generated table, so that the tables of the docs pages are never typed by
hand."""

from __future__ import annotations


def splice(text: str, begin: str, end: str, body: str) -> str:
    """``text`` with everything between the markers ``begin`` and ``end`` (each present
    exactly once, ValueError naming them otherwise) replaced by ``body``."""
    if text.count(begin) != 1 or text.count(end) != 1:
        raise ValueError(f"the file must hold the markers {begin!r} and {end!r} once each")
    head, rest = text.split(begin)
    _, tail = rest.split(end)
    return f"{head}{begin}\n{body.strip()}\n{end}{tail}"


def splice_generated(text: str, begin: str, end: str, markdown: str, source: str) -> str:
    """:func:`splice` of ``markdown`` headed by a line naming the experiment folder
    ``source`` that ``lonlib analyse`` generated it from."""
    body = f"*Generated from `{source}` by `lonlib analyse`.*\n\n{markdown.strip()}"
    return splice(text, begin, end, body)
