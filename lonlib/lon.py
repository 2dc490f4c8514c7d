"""Local Optima Networks from basin-hopping trials: the paper's model and the field's metrics.

Paper (§II-C): a node is an accepted local optimum, an edge the transition from the current
best to a new non-deteriorating optimum; a run's chain is a *monotonic sequence*, its first
node a *start node* and its last node (no outgoing edge) a *sink*. Beyond the paper, the
standard of Ochoa et al. (and of ``lonkit``): edge types improving / equal / worsening (the
*full* LON adds the rejected trials' optima with worsening edges), the MLON (no worsening
edges), the CMLON (plateaus of equal-fitness optima contracted), funnels, global sinks,
neutrality, strength of global sinks, global-funnel proportion, success, deviation and
in-strength.

Graphs are plain :class:`networkx.DiGraph` objects. The objective's sense is explicit
(``sense="max"``: the paper maximises fitness; ``"min"`` for the usual LON benchmarks), and
so is ``tolerance``: two fitness values closer than it count as equal. Both are stored as
graph attributes and every function honours them.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import networkx as nx
import numpy as np
import pandas as pd

from lonlib.store import p_label
from lonlib.validation import check_choice, check_range

TRACE_HEADER = ("run", "fit1", "node1", "fit2", "node2")


def node_id(p: float, run: int, index: int) -> str:
    """Name of the optimum found by local search ``index`` of run ``run`` at strength ``p``."""
    return f"p{p_label(p)}_r{run}_t{index}"


def edge_type(f_from: float, f_to: float, sense: str, tolerance: float) -> str:
    """``improving``, ``equal`` or ``worsening`` for a move from ``f_from`` to ``f_to``."""
    delta = (f_to - f_from) if sense == "max" else (f_from - f_to)
    if abs(delta) <= tolerance:
        return "equal"
    return "improving" if delta > 0 else "worsening"


def _new_graph(sense: str, tolerance: float) -> nx.DiGraph:
    check_choice("sense", sense, ("max", "min"))
    check_range("tolerance", tolerance, 0.0)
    return nx.DiGraph(sense=sense, tolerance=float(tolerance))


def _add_edge(graph: nx.DiGraph, source: str, target: str, run: Any) -> None:
    if graph.has_edge(source, target):
        graph.edges[source, target]["weight"] += 1
        return
    kind = edge_type(
        graph.nodes[source]["fitness"],
        graph.nodes[target]["fitness"],
        graph.graph["sense"],
        graph.graph["tolerance"],
    )
    graph.add_edge(source, target, type=kind, weight=1, run=str(run))


def build_lon(
    trials: pd.DataFrame, sense: str = "max", tolerance: float = 1e-9, full: bool = False
) -> nx.DiGraph:
    """The LON of stored trials (one or more p values and runs).

    Nodes carry ``fitness``, ``p``, ``run``, ``index``, ``start`` and ``accepted``; edges
    ``type`` and ``weight``. With ``full=True`` the rejected trials' optima join as nodes
    reached by worsening (or equal-but-rejected never happens: equal is accepted) edges.
    ``graph.graph["run_ends"]`` maps each run to its final incumbent (its sink).
    """
    graph = _new_graph(sense, tolerance)
    run_ends: dict[str, str] = {}
    for row in trials.sort_values(["p", "run", "index"]).itertuples():
        if not row.accepted and not full:
            continue
        name = node_id(row.p, row.run, row.index)
        graph.add_node(
            name,
            fitness=float(row.fitness),
            p=float(row.p),
            run=int(row.run),
            index=int(row.index),
            start=row.parent < 0,
            accepted=bool(row.accepted),
        )
        run_key = f"{p_label(row.p)}:{row.run}"
        if row.parent >= 0:
            _add_edge(graph, node_id(row.p, row.run, row.parent), name, run_key)
        if row.accepted:
            run_ends[run_key] = name
    graph.graph["run_ends"] = run_ends
    _annotate(graph)
    return graph


def _annotate(graph: nx.DiGraph) -> None:
    """Mark sinks (no outgoing non-worsening edge), the best node and in-strength."""
    best = best_fitness(graph)
    for name, data in graph.nodes(data=True):
        data["in_strength"] = int(sum(w for _, _, w in graph.in_edges(name, data="weight")))
        monotone_out = [t for _, _, t in graph.out_edges(name, data="type") if t != "worsening"]
        data["sink"] = data.get("accepted", True) and not monotone_out
        data["best"] = best is not None and _equal(graph, data["fitness"], best)


def _equal(graph: nx.DiGraph, a: float, b: float) -> bool:
    return abs(a - b) <= graph.graph["tolerance"]


def best_fitness(graph: nx.DiGraph) -> float | None:
    """Best fitness in the graph under its sense (None for an empty graph)."""
    values = [f for _, f in graph.nodes(data="fitness")]
    if not values:
        return None
    return max(values) if graph.graph["sense"] == "max" else min(values)


def mlon(graph: nx.DiGraph) -> nx.DiGraph:
    """The monotonic LON: the graph without worsening edges (and the nodes only they reach)."""
    keep = [(u, v) for u, v, t in graph.edges(data="type") if t != "worsening"]
    out = graph.edge_subgraph(keep).copy()
    out.add_nodes_from((n, d) for n, d in graph.nodes(data=True) if d.get("accepted", True))
    out.graph.update(graph.graph)
    return out


def cmlon(graph: nx.DiGraph) -> nx.DiGraph:
    """The compressed MLON: connected plateaus of equal-fitness optima become one node.

    Node attributes: ``fitness``, ``size`` (optima contracted), ``members``; edges carry the
    summed ``weight`` of the improving transitions between plateaus.
    """
    monotone = mlon(graph)
    equal = nx.Graph()
    equal.add_nodes_from(monotone)
    equal.add_edges_from((u, v) for u, v, t in monotone.edges(data="type") if t == "equal")
    out = _new_graph(graph.graph["sense"], graph.graph["tolerance"])
    owner = {}
    for i, members in enumerate(sorted(nx.connected_components(equal), key=min)):
        name = f"c{i}"
        fitness = monotone.nodes[min(members)]["fitness"]
        out.add_node(name, fitness=fitness, size=len(members), members=sorted(members))
        owner.update(dict.fromkeys(members, name))
    for u, v, data in monotone.edges(data=True):
        a, b = owner[u], owner[v]
        if a == b:
            continue
        if out.has_edge(a, b):
            out.edges[a, b]["weight"] += data["weight"]
        else:
            out.add_edge(a, b, type="improving", weight=data["weight"])
    return out


def sinks(graph: nx.DiGraph) -> list[str]:
    """Nodes of the MLON without an outgoing edge: ends of monotonic sequences."""
    monotone = mlon(graph)
    return [n for n in monotone if monotone.out_degree(n) == 0]


def lon_metrics(graph: nx.DiGraph) -> dict[str, float]:
    """The paper's counts and the field's standard metrics for one LON.

    * ``optima``, ``edges``, ``improving``, ``equal``, ``worsening``: sizes;
    * ``sinks`` / ``global_sinks``: MLON sinks, and those at the best fitness;
    * ``funnels``: sinks of the CMLON; ``neutral``: 1 - CMLON nodes / MLON nodes;
    * ``strength_global_sinks``: share of all MLON edge weight entering global sinks;
    * ``global_funnel_proportion``: share of MLON nodes from which a global sink is reachable;
    * ``success``: share of runs ending at the best fitness; ``deviation``: mean distance of
      the runs' final fitness from the best; ``best``: the best fitness.
    """
    monotone = mlon(graph)
    best = best_fitness(monotone)
    types = [t for _, _, t in graph.edges(data="type")]
    sink_nodes = [n for n in monotone if monotone.out_degree(n) == 0]
    global_sinks = [n for n in sink_nodes if _equal(graph, monotone.nodes[n]["fitness"], best)]
    compressed = cmlon(graph)
    total_weight = sum(w for _, _, w in monotone.edges(data="weight"))
    into_global = sum(w for n in global_sinks for _, _, w in monotone.in_edges(n, data="weight"))
    reach = set()
    for n in global_sinks:
        reach |= nx.ancestors(monotone, n) | {n}
    ends = [graph.nodes[n]["fitness"] for n in graph.graph.get("run_ends", {}).values()]
    return {
        "optima": monotone.number_of_nodes(),
        "edges": len(types),
        "improving": types.count("improving"),
        "equal": types.count("equal"),
        "worsening": types.count("worsening"),
        "sinks": len(sink_nodes),
        "global_sinks": len(global_sinks),
        "funnels": sum(1 for n in compressed if compressed.out_degree(n) == 0),
        "neutral": 1.0 - compressed.number_of_nodes() / max(monotone.number_of_nodes(), 1),
        "strength_global_sinks": into_global / total_weight if total_weight else float("nan"),
        "global_funnel_proportion": len(reach) / max(monotone.number_of_nodes(), 1),
        "success": float(np.mean([_equal(graph, f, best) for f in ends])) if ends else np.nan,
        "deviation": float(np.mean([abs(f - best) for f in ends])) if ends else np.nan,
        "best": best if best is not None else float("nan"),
        "runs": len(ends),
    }


def metrics_table(
    trials: pd.DataFrame, sense: str = "max", tolerance: float = 1e-9
) -> pd.DataFrame:
    """:func:`lon_metrics` per perturbation strength, one row per p."""
    rows = []
    for p, group in trials.groupby("p", sort=True):
        rows.append({"p": p, **lon_metrics(build_lon(group, sense, tolerance))})
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------------- I/O
def to_trace(graph: nx.DiGraph, path: str | Path) -> None:
    """Write the standard trace format: header ``run fit1 node1 fit2 node2``, one
    whitespace-separated row per edge (transition), in run order."""
    lines = [" ".join(TRACE_HEADER)]
    for u, v, data in sorted(graph.edges(data=True), key=lambda e: (e[2]["run"], e[0], e[1])):
        for _ in range(data["weight"]):
            f1, f2 = graph.nodes[u]["fitness"], graph.nodes[v]["fitness"]
            lines.append(f"{data['run']} {f1!r} {u} {f2!r} {v}")
    Path(path).write_text("\n".join(lines) + "\n")


def from_trace(path: str | Path, sense: str = "min", tolerance: float = 1e-9) -> nx.DiGraph:
    """Read a trace file (``run fit1 node1 fit2 node2``) sampled by lonlib or another tool.

    Most LON tools minimise, hence ``sense="min"`` by default; say ``"max"`` for lonlib's
    own traces. A node's first row is a start node of its run; the last ``node2`` of a run
    is the run's end.
    """
    path = Path(path)
    graph = _new_graph(sense, tolerance)
    rows = _read_trace_rows(path)
    run_ends: dict[str, str] = {}
    for line_no, (run, f1, n1, f2, n2) in rows:
        for name, fitness in ((n1, f1), (n2, f2)):
            if name in graph and not np.isclose(
                graph.nodes[name]["fitness"], fitness, rtol=0, atol=tolerance
            ):
                raise ValueError(f"{path}:{line_no}: node {name} has two fitness values")
            if name not in graph:
                graph.add_node(
                    name, fitness=fitness, run=run, start=run not in run_ends, accepted=True
                )
        kind = edge_type(f1, f2, sense, tolerance)
        graph.nodes[n2]["accepted"] = graph.nodes[n2]["accepted"] and kind != "worsening"
        _add_edge(graph, n1, n2, run)
        if kind != "worsening":
            run_ends[run] = n2
        else:
            run_ends.setdefault(run, n1)
    graph.graph["run_ends"] = run_ends
    _annotate(graph)
    return graph


def _read_trace_rows(path: Path) -> Iterable[tuple[int, tuple[str, float, str, float, str]]]:
    try:
        lines = path.read_text().splitlines()
    except OSError as error:
        raise ValueError(f"{path}: cannot read the trace ({error})") from None
    if not lines or tuple(lines[0].split()) != TRACE_HEADER:
        raise ValueError(f"{path}: the first line must be the header {' '.join(TRACE_HEADER)!r}")
    out = []
    for line_no, line in enumerate(lines[1:], start=2):
        parts = line.split()
        if not parts:
            continue
        if len(parts) != 5:
            raise ValueError(f"{path}:{line_no}: expected 5 fields, got {len(parts)}")
        try:
            out.append((line_no, (parts[0], float(parts[1]), parts[2], float(parts[3]), parts[4])))
        except ValueError:
            raise ValueError(f"{path}:{line_no}: fitness values must be numbers") from None
    return out


def to_graphml(graph: nx.DiGraph, path: str | Path) -> None:
    """Write GraphML (list-valued attributes are joined with spaces)."""
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
