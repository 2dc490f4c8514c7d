"""Generated tables in Markdown files: the text between a pair of marker comments is
replaced by a generated table, so that the tables of the docs pages are never typed by
hand."""

from __future__ import annotations


def marker_opening(begin: str) -> str:
    """The part of a begin marker that identifies it: ``<!-- summary:begin`` of
    ``<!-- summary:begin (lonlib analyse data/reference --docs docs/results.md) -->``. The
    rest of the comment is free text (the command that fills the block), so that every
    page names its own command."""
    return begin.split(" (", 1)[0].removesuffix(" -->")


def has_markers(text: str, begin: str) -> bool:
    """Does ``text`` hold the begin marker ``begin`` (identified by :func:`marker_opening`)?"""
    return marker_opening(begin) in text


def splice(text: str, begin: str, end: str, body: str) -> str:
    """``text`` with everything between the markers ``begin`` and ``end`` (each present
    exactly once, ValueError naming them otherwise) replaced by ``body``. The begin marker
    is found by :func:`marker_opening` and its comment is kept as the page wrote it."""
    opening = marker_opening(begin)
    if text.count(opening) != 1 or text.count(end) != 1:
        raise ValueError(f"the file must hold the markers {begin!r} and {end!r} once each")
    head, rest = text.split(opening)
    if "-->" not in rest.split(end)[0]:
        raise ValueError(f"the begin marker {begin!r} must be a complete comment (... -->)")
    comment, rest = rest.split("-->", 1)
    _, tail = rest.split(end)
    return f"{head}{opening}{comment}-->\n{body.strip()}\n{end}{tail}"


def splice_generated(text: str, begin: str, end: str, markdown: str, source: str) -> str:
    """:func:`splice` of ``markdown`` headed by a line naming the experiment folder
    ``source`` that ``lonlib analyse`` generated it from."""
    body = f"*Generated from `{source}` by `lonlib analyse`.*\n\n{markdown.strip()}"
    return splice(text, begin, end, body)
