"""The field's LON metrics, each on the graph it is defined on (LON, MLON or CMLON).

Sources: Ochoa et al.'s LON/CMLON analyses (e.g. Ochoa, Veerapen, Daolio, Tomassini, EvoCOP
2017, and the R scripts published with them) and the Python peer library ``lonkit``; the paper
this package implements defines optima, monotonic sequences and sinks. :data:`METRICS` lists
every metric of :func:`lon_metrics` with its graph, definition and source; the README's LON
section shows the same table. Funnel metrics are CMLON metrics, so a plateau of equal-fitness
global optima counts as one global funnel.
"""

from __future__ import annotations

from dataclasses import dataclass

import igraph
import networkx as nx
import numpy as np
import pandas as pd

from lonlib.lon.graphs import (
    EQUAL,
    IMPROVING,
    WORSENING,
    Compressed,
    build_lon,
    compress,
    graph_arrays,
)


@dataclass(frozen=True)
class Metric:
    """One entry of the metrics table: the graph it is computed on, its definition, source."""

    name: str
    graph: str
    definition: str
    source: str


METRICS = (
    Metric("optima", "MLON", "accepted local optima (nodes)", "paper §II-C"),
    Metric("edges", "LON", "distinct transitions between two different optima", "Ochoa et al."),
    Metric("improving", "LON", "edges to a better optimum", "Ochoa et al."),
    Metric(
        "equal", "LON", "edges to an optimum equal within the fitness tolerance", "Ochoa et al."
    ),
    Metric("worsening", "LON", "edges to a worse optimum (full LON only)", "Ochoa et al."),
    Metric("self_returns", "LON", "hops that returned to the optimum they left", "lonkit"),
    Metric("sinks", "MLON", "optima without an outgoing edge (ends of monotonic sequences)",
           "paper §II-C"),
    Metric("global_sinks", "MLON", "sinks at the best fitness", "paper, Ochoa et al."),
    Metric("neutral_optima", "MLON", "share of optima with at least one equal edge",
           "lonkit (LON `neutral`)"),
    Metric("cmlon_nodes", "CMLON", "plateaus (contracted optima)", "Ochoa et al."),
    Metric("neutral", "CMLON", "1 - CMLON nodes / MLON nodes", "Ochoa et al.; lonkit (CMLON)"),
    Metric("funnels", "CMLON", "sinks of the CMLON", "Ochoa et al."),
    Metric("global_funnels", "CMLON", "funnels at the best fitness", "Ochoa et al."),
    Metric("strength_global_sinks", "CMLON",
           "weighted in-strength of the global funnels / that of all funnels",
           "Ochoa et al. (`gstrength`); lonkit `sink_strength`"),
    Metric("global_strength", "CMLON",
           "weighted in-strength of the global funnels / that of all CMLON nodes",
           "lonkit (CMLON `global_strength`)"),
    Metric("global_funnel_proportion", "CMLON",
           "share of CMLON nodes from which a global funnel is reachable (itself included)",
           "Ochoa et al.; lonkit"),
    Metric("success", "runs", "share of runs whose final optimum is at the best fitness",
           "Ochoa et al.; lonkit"),
    Metric("deviation", "runs", "mean |final fitness - best fitness| over runs",
           "Ochoa et al.; lonkit"),
    Metric("best", "MLON", "best fitness of the accepted optima", ""),
    Metric("runs", "runs", "number of runs", ""),
)  # fmt: skip


def lon_metrics(graph: nx.DiGraph) -> dict[str, float]:
    """Every metric of :data:`METRICS` for one LON (built by :func:`~lonlib.lon.graphs.build_lon`
    or :func:`~lonlib.lon.graphs.lon_from_transitions`), each on its graph: sizes on the LON, sinks
    on the MLON, funnels and their strength and reach on the CMLON, success and deviation
    on the runs' final optima (``graph.graph["run_ends"]``). "Equal" and "at the best
    fitness" mean within the graph's fitness tolerance. A ratio whose denominator is zero is NaN
    (for instance strengths when no funnel has an incoming edge).
    """
    arrays = graph_arrays(graph)
    best = arrays.best
    best_value = np.nan if best is None else best
    n_optima = int(arrays.accepted.sum())
    sink = arrays.sinks
    plateau_edges = arrays.monotone & (arrays.kind == EQUAL)
    on_plateau = np.zeros(len(arrays.names), bool)
    on_plateau[arrays.source[plateau_edges]] = True
    on_plateau[arrays.target[plateau_edges]] = True
    compressed = compress(arrays)
    funnels = compressed.funnels
    global_funnels = funnels[arrays.at_best(compressed.fitness[funnels])]
    strength = compressed.in_strength
    ends = np.array(
        [graph.nodes[n]["fitness"] for n in graph.graph.get("run_ends", {}).values()], float
    )
    return {
        "optima": n_optima,
        "edges": len(arrays.kind),
        "improving": int((arrays.kind == IMPROVING).sum()),
        "equal": int((arrays.kind == EQUAL).sum()),
        "worsening": int((arrays.kind == WORSENING).sum()),
        "self_returns": int(arrays.self_returns.sum()),
        "sinks": int(sink.sum()),
        "global_sinks": int((sink & arrays.at_best(arrays.fitness)).sum()),
        "neutral_optima": _ratio(int((on_plateau & arrays.accepted).sum()), n_optima),
        "cmlon_nodes": len(compressed.fitness),
        "neutral": 1.0 - _ratio(len(compressed.fitness), n_optima) if n_optima else np.nan,
        "funnels": len(funnels),
        "global_funnels": len(global_funnels),
        "strength_global_sinks": _ratio(strength[global_funnels].sum(), strength[funnels].sum()),
        "global_strength": _ratio(strength[global_funnels].sum(), strength.sum()),
        "global_funnel_proportion": _ratio(
            len(_basin(compressed, global_funnels)), len(compressed.fitness)
        ),
        "success": float(np.mean(arrays.at_best(ends))) if ends.size else np.nan,
        "deviation": float(np.mean(np.abs(ends - best_value))) if ends.size else np.nan,
        "best": best_value,
        "runs": int(ends.size),
    }


def _ratio(part: float, whole: float) -> float:
    return float(part) / float(whole) if whole else float("nan")


def _cmlon_igraph(compressed: Compressed) -> igraph.Graph:
    edges = np.column_stack([compressed.source, compressed.target])
    return igraph.Graph(n=len(compressed.fitness), edges=edges.tolist(), directed=True)


def _basin(compressed: Compressed, targets: np.ndarray) -> set[int]:
    """CMLON nodes from which any of ``targets`` is reachable (the targets included)."""
    if len(targets) == 0:
        return set()
    graph = _cmlon_igraph(compressed)
    reach = graph.neighborhood(targets.tolist(), order=graph.vcount(), mode="in")
    return set().union(*reach)


def node_metrics(graph: nx.DiGraph) -> pd.DataFrame:
    """Per-node metrics on the graph given (a LON, an MLON or a CMLON), indexed by name:
    ``fitness``; ``in_strength`` (summed weight of the edges entering the node: how often
    the search arrived there from another optimum); ``out_degree`` (distinct optima it led
    to); ``self_returns``; ``sink`` (no outgoing non-worsening edge to an accepted optimum);
    ``best`` (at the best fitness within the fitness tolerance)."""
    arrays = graph_arrays(graph)
    n = len(arrays.names)
    return pd.DataFrame(
        {
            "fitness": arrays.fitness,
            "in_strength": np.bincount(arrays.target, arrays.weight, n).astype(int),
            "out_degree": np.bincount(arrays.source, minlength=n),
            "self_returns": arrays.self_returns,
            "sink": arrays.sinks,
            "best": arrays.at_best(arrays.fitness),
        },
        index=pd.Index(arrays.names, name="node"),
    )


def funnel_metrics(graph: nx.DiGraph) -> pd.DataFrame:
    """One row per funnel of the LON's CMLON (named as in :func:`~lonlib.lon.graphs.cmlon`):
    ``fitness``, ``size`` (optima in the funnel's plateau), ``global``, ``in_strength``
    (summed weight of its incoming CMLON edges), and its basin: ``basin_nodes`` (CMLON
    nodes from which it is reachable, itself included), ``basin_share`` (the same over all
    CMLON nodes) and ``basin_optima`` (the MLON optima those nodes contract). Basins of
    different funnels may overlap (Ochoa et al.)."""
    arrays = graph_arrays(graph)
    compressed = compress(arrays)
    funnels = compressed.funnels
    reach = _cmlon_igraph(compressed).neighborhood(
        funnels.tolist(), order=len(compressed.fitness), mode="in"
    )
    names = compressed.names
    return pd.DataFrame(
        {
            "fitness": compressed.fitness[funnels],
            "size": compressed.size[funnels],
            "global": arrays.at_best(compressed.fitness[funnels]),
            "in_strength": compressed.in_strength[funnels].astype(int),
            "basin_nodes": [len(r) for r in reach],
            "basin_share": [len(r) / len(compressed.fitness) for r in reach],
            "basin_optima": [int(compressed.size[r].sum()) for r in reach],
        },
        index=pd.Index([names[k] for k in funnels], name="funnel"),
    )


def metrics_table(
    trials: pd.DataFrame, sense: str = "max", fitness_tolerance: float = 1e-9
) -> pd.DataFrame:
    """:func:`lon_metrics` per perturbation strength, one row per p."""
    rows = []
    for p, group in trials.groupby("p", sort=True):
        rows.append({"p": p, **lon_metrics(build_lon(group, sense, fitness_tolerance))})
    return pd.DataFrame(rows)
