"""LON files: the standard trace format (``run fit1 node1 fit2 node2``), GraphML, igraph."""

from __future__ import annotations

from pathlib import Path

import networkx as nx
import numpy as np
import pandas as pd

from lonlib.lon.graphs import TRANSITION_COLUMNS, lon_from_transitions

TRACE_HEADER = TRANSITION_COLUMNS


def to_trace(graph: nx.DiGraph, path: str | Path) -> None:
    """Write the standard trace format: header ``run fit1 node1 fit2 node2``, then one
    whitespace-separated row per hop: each edge ``weight`` times under its ``run``, in the
    order of its first occurrence, and each node's ``self_returns`` as ``a -> a`` rows right
    after the first edge into it. Runs and run ends read back exactly when runs share no
    edge (always so for lonlib's own LONs); a node without edges or self-returns cannot be
    written in this format."""
    fitness = dict(graph.nodes(data="fitness"))
    rows: list[tuple[float, str, str, str]] = []
    first_in: dict[str, float] = {}
    for u, v, data in graph.edges(data=True):
        order = float(data.get("order", 0))
        rows += [(order, data["run"], u, v)] * data["weight"]
        first_in[v] = min(first_in.get(v, order), order)
    for node, count in graph.nodes(data="self_returns", default=0):
        if count:
            order = first_in.get(node, -1.0) + 0.5
            rows += [(order, str(graph.nodes[node].get("run", "")), node, node)] * count
    rows.sort(key=lambda row: row[0])
    lines = [" ".join(TRACE_HEADER)]
    lines += [f"{run} {fitness[u]!r} {u} {fitness[v]!r} {v}" for _, run, u, v in rows]
    Path(path).write_text("\n".join(lines) + "\n")


def read_trace(path: str | Path) -> pd.DataFrame:
    """The rows of a trace file as a table (columns ``run fit1 node1 fit2 node2``; runs and
    node names as strings). A malformed file raises ``ValueError`` naming file and line."""
    return pd.DataFrame(_read_columns(Path(path)))


def _read_columns(path: Path) -> dict[str, np.ndarray]:
    """The trace's columns as arrays (a plain split: faster than a CSV reader here)."""
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: cannot read the trace ({error})") from None
    if not lines or tuple(lines[0].split()) != TRACE_HEADER:
        raise ValueError(f"{path}: the first line must be the header {' '.join(TRACE_HEADER)!r}")
    rows = [line.split() for line in lines[1:]]
    sizes = set(map(len, rows))
    if sizes - {0, 5}:
        line_no, row = next((i, r) for i, r in enumerate(rows, start=2) if len(r) not in (0, 5))
        raise ValueError(f"{path}:{line_no}: expected 5 fields, got {len(row)}")
    if 0 in sizes:
        rows = [row for row in rows if row]
    run, fit1, node1, fit2, node2 = zip(*rows, strict=True) if rows else ((),) * 5
    try:
        fits = [np.array(fit1, float), np.array(fit2, float)]
        finite = all(np.isfinite(f).all() for f in fits)
    except ValueError:
        finite = False
    if not finite:
        bad = next(i for i, r in enumerate(rows) if not _finite_numbers(r[1], r[3]))
        line_no = [i for i, r in enumerate(lines[1:], start=2) if r.split()][bad]
        raise ValueError(f"{path}:{line_no}: fitness values must be finite numbers")
    names = [np.array(values, dtype=object) for values in (run, node1, node2)]
    return dict(zip(TRACE_HEADER, [names[0], fits[0], names[1], fits[1], names[2]], strict=True))


def _finite_numbers(*texts: str) -> bool:
    try:
        return all(np.isfinite(float(t)) for t in texts)
    except ValueError:
        return False


def from_trace(
    path: str | Path,
    sense: str = "min",
    fitness_tolerance: float = 1e-9,
    max_fitness_spread: float | None = None,
) -> nx.DiGraph:
    """The LON of a trace file sampled by lonlib or another tool (see
    :func:`~lonlib.lon.graphs.lon_from_transitions` for how nodes, self-returns, noisy fitness and
    run ends are read).

    Most LON tools minimise, hence ``sense="min"`` by default; say ``"max"`` for lonlib's
    own traces. ``fitness_tolerance`` is the equal-edge tolerance; ``max_fitness_spread`` the
    separate bound on how far a node's repeated fitness values may differ before the file
    is refused (None: never refused, only warned about).
    """
    return lon_from_transitions(
        _read_columns(Path(path)), sense, fitness_tolerance, max_fitness_spread, source=str(path)
    )


def to_graphml(graph: nx.DiGraph, path: str | Path) -> None:
    """Write GraphML (list-valued attributes are joined with spaces; only scalar graph
    attributes are kept)."""
    out = graph.copy()
    out.graph = {k: v for k, v in graph.graph.items() if isinstance(v, (str, int, float))}
    for _, data in out.nodes(data=True):
        for key, value in list(data.items()):
            if isinstance(value, (list, tuple)):
                data[key] = " ".join(map(str, value))
    nx.write_graphml(out, path)


def to_igraph(graph: nx.DiGraph):
    """The same graph as an :class:`igraph.Graph` (node names in the ``_nx_name`` attr)."""
    import igraph

    return igraph.Graph.from_networkx(graph)
