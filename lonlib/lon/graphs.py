"""The three graphs of a Local Optima Network: LON, MLON and CMLON.

Paper (§II-C): a node is an accepted local optimum, an edge the transition from the current
best to a new non-deteriorating optimum; a run's chain is a *monotonic sequence*, its first
node a *start node* and its last node (no outgoing edge) a *sink*. Beyond the paper, the
standard of Ochoa et al. (and of the Python peer library ``lonkit``):

* **LON**: every sampled transition between two *different* optima, typed ``improving`` /
  ``equal`` / ``worsening``; the *full* LON adds the rejected trials' optima, reached by
  worsening edges. A hop that returns to the optimum it left is a **self-return**: never an
  edge, counted per node in ``self_returns`` (so a node whose only moves return to itself is
  a sink).
* **MLON** (monotonic LON): the accepted optima and the non-worsening edges between them.
* **CMLON** (compressed MLON): every edge of the MLON whose two ends are equal within the
  fitness tolerance is contracted, repeatedly, until none is left (approximate equality is not
  transitive, so one pass is not enough); a plateau takes the best fitness of its members.
  Edges that end up worsening between plateaus are dropped (counted in
  ``graph.graph["dropped_worsening"]``), so every CMLON edge is improving.

Graphs are plain :class:`networkx.DiGraph` objects; the heavy lifting runs on the arrays of
:func:`graph_arrays` (numpy, scipy). The objective's sense is explicit (``sense="max"``: the
paper maximises fitness; ``"min"`` for the usual LON benchmarks), and so is ``fitness_tolerance``:
two fitness values at most that far apart count as equal. Both are graph attributes that
every function honours. The metrics live in :mod:`lonlib.lon.metrics`, the file formats in
:mod:`lonlib.lon.io`.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import networkx as nx
import numpy as np
import pandas as pd
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from lonlib.util.labels import p_label
from lonlib.util.validation import check_choice, check_range

EDGE_TYPES = ("improving", "equal", "worsening")
IMPROVING, EQUAL, WORSENING = range(3)
TRANSITION_COLUMNS = ("run", "fit1", "node1", "fit2", "node2")


class FitnessSpreadWarning(UserWarning):
    """A node was seen with several fitness values; the LON keeps its best one."""


def node_id(p: float, run: int, index: int) -> str:
    """Name of the optimum found by local search ``index`` of run ``run`` at strength ``p``."""
    return _node_name(p_label(p), run, index)


def _node_name(label: str, run: int, index: int) -> str:
    return f"p{label}_r{run}_t{index}"


def edge_types(
    f_from: np.ndarray, f_to: np.ndarray, sense: str, fitness_tolerance: float
) -> np.ndarray:
    """Codes of :data:`EDGE_TYPES` (0 improving, 1 equal, 2 worsening) for moves, vectorised."""
    delta = np.subtract(f_to, f_from) if sense == "max" else np.subtract(f_from, f_to)
    return np.where(
        np.abs(delta) <= fitness_tolerance, EQUAL, np.where(delta > 0, IMPROVING, WORSENING)
    )


def edge_type(f_from: float, f_to: float, sense: str, fitness_tolerance: float) -> str:
    """``improving``, ``equal`` or ``worsening`` for a move from ``f_from`` to ``f_to``."""
    return EDGE_TYPES[int(edge_types(f_from, f_to, sense, fitness_tolerance))]


def _check_sense_tolerance(sense: str, fitness_tolerance: float) -> None:
    check_choice("sense", sense, ("max", "min"))
    check_range("fitness_tolerance", fitness_tolerance, 0.0)


def _best(values: np.ndarray, sense: str) -> float | None:
    if values.size == 0:
        return None
    return float(values.max() if sense == "max" else values.min())


# ------------------------------------------------------------------------------ LON
def build_lon(
    trials: pd.DataFrame, sense: str = "max", fitness_tolerance: float = 1e-9, full: bool = False
) -> nx.DiGraph:
    """The LON of stored trials (one or more p values and runs).

    Nodes carry ``fitness``, ``p``, ``run``, ``index``, ``start``, ``accepted`` and the
    annotations of every LON (``self_returns``, ``in_strength``, ``sink``, ``best``); edges
    ``type``, ``weight``, ``run`` and ``order`` (position of the transition's first
    occurrence in run order). With ``full=True`` the rejected trials' optima join as nodes
    reached by worsening edges. ``graph.graph["run_ends"]`` maps each run (``"<p>:<run>"``)
    to its final incumbent.
    """
    _check_sense_tolerance(sense, fitness_tolerance)
    rows = trials.sort_values(["p", "run", "index"], kind="stable")
    if not full:
        rows = rows[rows["accepted"].to_numpy(bool)]
    labels = {p: p_label(p) for p in rows["p"].unique()}
    p, run, index = (rows[c].to_numpy() for c in ("p", "run", "index"))
    parent = rows["parent"].to_numpy()
    names = [_node_name(labels[a], b, c) for a, b, c in zip(p, run, index, strict=True)]
    run_keys = np.array([f"{labels[a]}:{b}" for a, b in zip(p, run, strict=True)], dtype=object)
    position = pd.Index(names)
    child = np.flatnonzero(parent >= 0)
    parents = [_node_name(labels[p[i]], run[i], parent[i]) for i in child]
    source = position.get_indexer(parents)
    if (source < 0).any():
        missing = parents[int(np.argmax(source < 0))]
        raise ValueError(f"trials: parent {missing} of a trial is not an accepted trial")
    accepted = rows["accepted"].to_numpy(bool)
    last = pd.Series(np.arange(len(rows)))[accepted].groupby(run_keys[accepted]).last()
    nodes = {
        "fitness": rows["fitness"].to_numpy(float),
        "p": p.astype(float),
        "run": run.astype(int),
        "index": index.astype(int),
        "start": parent < 0,
        "accepted": accepted,
    }
    if "label" in rows:  # behaviour labels (lonlib.task.behaviour), where the trials carry them
        nodes["label"] = rows["label"].fillna("").astype(str).to_numpy(object)
    return assemble_lon(
        names,
        nodes,
        Transitions(source, child, run_keys[child], child),
        {key: names[i] for key, i in last.items()},
        sense,
        fitness_tolerance,
    )


def lon_from_transitions(
    transitions: pd.DataFrame | Mapping[str, Sequence],
    sense: str = "min",
    fitness_tolerance: float = 1e-9,
    max_fitness_spread: float | None = None,
    source: str = "transitions",
) -> nx.DiGraph:
    """The LON of a transition table (columns ``run fit1 node1 fit2 node2``, one row per hop,
    each run's rows in the order they happened), as written by lonlib or another LON tool;
    a DataFrame or a mapping of column name to values. Run labels become strings.

    A node seen with several fitness values (a tool re-evaluating an optimum, ~1e-8 apart)
    takes its best one under ``sense``; a :class:`FitnessSpreadWarning` names the largest
    spread, and a ``ValueError`` is raised only when that spread exceeds
    ``max_fitness_spread`` (None: no bound). ``fitness_tolerance`` is the separate equal-edge
    tolerance, applied to the aggregated values. A row whose two nodes are the same is a
    self-return. A node is ``accepted`` when the search stood on it: it leaves a hop
    (``node1``) or a non-worsening hop reaches it; the ``start`` nodes are the ``node1`` of
    each run's first row, and a run ends at the ``node2`` of its last non-worsening row (at
    its start when it has none). ``source`` names the table in messages.
    """
    _check_sense_tolerance(sense, fitness_tolerance)
    if max_fitness_spread is not None:
        check_range("max_fitness_spread", max_fitness_spread, 0.0)
    missing = [c for c in TRANSITION_COLUMNS if c not in transitions]
    if missing:
        raise ValueError(f"{source}: missing columns {missing} (need {TRANSITION_COLUMNS})")
    node1, node2 = (np.asarray(transitions[c], dtype=object) for c in ("node1", "node2"))
    m = len(node1)
    pairs = np.column_stack([node1, node2])
    codes, names = pd.factorize(pairs.ravel())  # nodes in order of first appearance
    values = np.column_stack([transitions["fit1"], transitions["fit2"]]).astype(float).ravel()
    fitness = _aggregate_fitness(codes, values, names, sense, max_fitness_spread, source)
    src, dst = codes[0::2], codes[1::2]
    runs = np.array([str(r) for r in transitions["run"]], dtype=object)
    kind = edge_types(fitness[src], fitness[dst], sense, fitness_tolerance)
    accepted = np.zeros(len(names), bool)
    accepted[src] = True
    accepted[dst[kind != WORSENING]] = True
    first_row = np.full(len(names), m)
    np.minimum.at(first_row, codes, np.repeat(np.arange(m), 2))
    run_names, starts, ends = _run_starts_and_ends(runs, src, dst, kind)
    start = np.zeros(len(names), bool)
    start[starts] = True
    nodes = {
        "fitness": fitness,
        "run": runs[first_row] if m else np.array([], object),
        "start": start,
        "accepted": accepted,
    }
    names = list(names)
    return assemble_lon(
        names,
        nodes,
        Transitions(src, dst, runs, np.arange(m)),
        {run: names[end] for run, end in zip(run_names, ends, strict=True)},
        sense,
        fitness_tolerance,
    )


def _run_starts_and_ends(
    runs: np.ndarray, src: np.ndarray, dst: np.ndarray, kind: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each run's label, start node (``node1`` of its first row) and end node (``node2`` of
    its last non-worsening row, else its start)."""
    run_codes, run_names = pd.factorize(runs)
    rows = np.arange(len(runs))
    first = np.full(len(run_names), len(runs))
    np.minimum.at(first, run_codes, rows)
    last = np.full(len(run_names), -1)
    moved = rows[kind != WORSENING]
    np.maximum.at(last, run_codes[moved], moved)
    starts = src[first]
    return run_names, starts, np.where(last >= 0, dst[np.maximum(last, 0)], starts)


def _aggregate_fitness(
    codes: np.ndarray,
    values: np.ndarray,
    names: np.ndarray,
    sense: str,
    max_spread: float | None,
    source: str,
) -> np.ndarray:
    """Each node's best value; warn on (and, past ``max_spread``, refuse) differing values."""
    low, high = np.full(len(names), np.inf), np.full(len(names), -np.inf)
    np.minimum.at(low, codes, values)
    np.maximum.at(high, codes, values)
    spread = high - low
    if len(names) and spread.max() > 0:
        worst = int(np.argmax(spread))
        message = (
            f"{source}: {int((spread > 0).sum())} node(s) seen with several fitness values; "
            f"the largest spread is {spread[worst]:.3g} (node {names[worst]})"
        )
        if max_spread is not None and spread[worst] > max_spread:
            raise ValueError(f"{message}, above max_fitness_spread={max_spread:g}")
        best = "max" if sense == "max" else "min"
        warnings.warn(f"{message}; each node keeps its {best}", FitnessSpreadWarning, 3)
    return high if sense == "max" else low


@dataclass(frozen=True)
class Transitions:
    """Hops in run order: node indices, the run label of each hop and its position."""

    source: np.ndarray
    target: np.ndarray
    run: np.ndarray
    order: np.ndarray


def assemble_lon(
    names: list[str],
    nodes: dict[str, np.ndarray],
    hops: Transitions,
    run_ends: dict[str, str],
    sense: str,
    fitness_tolerance: float,
) -> nx.DiGraph:
    """The LON graph of named nodes and hops: self-returns counted, repeated hops weighted."""
    n = len(names)
    fitness = nodes["fitness"]
    loop = hops.source == hops.target
    self_returns = np.bincount(hops.source[loop], minlength=n)
    src, dst = hops.source[~loop], hops.target[~loop]
    key, first, inverse = _unique_pairs(src * n + dst)
    weight = np.bincount(inverse, minlength=key.size)
    src, dst = key // max(n, 1), key % max(n, 1)
    kind = edge_types(fitness[src], fitness[dst], sense, fitness_tolerance)
    accepted = nodes["accepted"]
    monotone = (kind != WORSENING) & accepted[src] & accepted[dst]
    best = _best(fitness[accepted], sense)
    annotations = {
        "self_returns": self_returns,
        "in_strength": np.bincount(dst, weights=weight, minlength=n).astype(int),
        "sink": accepted & (np.bincount(src[monotone], minlength=n) == 0),
        "best": np.zeros(n, bool) if best is None else np.abs(fitness - best) <= fitness_tolerance,
    }
    runs, order = hops.run[~loop][first].tolist(), hops.order[~loop][first].tolist()
    edges = (
        (names[u], names[v], {"type": EDGE_TYPES[t], "weight": w, "run": str(r), "order": o})
        for u, v, t, w, r, o in zip(
            src.tolist(), dst.tolist(), kind.tolist(), weight.tolist(), runs, order, strict=True
        )
    )
    graph = nx.DiGraph(sense=sense, fitness_tolerance=float(fitness_tolerance), run_ends=run_ends)
    _fill(graph, names, {**nodes, **annotations}, edges)
    return graph


def _fill(
    graph: nx.DiGraph, names: list[str], columns: dict[str, np.ndarray | list], edges: Iterable
) -> None:
    """Add named nodes with one attribute per column, then the edges."""
    graph.add_nodes_from(names)
    keys = list(columns)
    values = (c.tolist() if isinstance(c, np.ndarray) else c for c in columns.values())
    rows = zip(*values, strict=True)
    attributes = (dict(zip(keys, row, strict=True)) for row in rows)
    # One call with a dict per node: much faster than add_nodes_from((name, dict), ...).
    nx.set_node_attributes(graph, dict(zip(names, attributes, strict=True)))
    graph.add_edges_from(edges)


def _unique_pairs(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distinct keys, the index of each one's first occurrence, and each key's group."""
    unique, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return unique, first, inverse


# ----------------------------------------------------------------------- arrays view
@dataclass(frozen=True)
class GraphArrays:
    """A LON (or any graph of this module) as arrays: node ``i`` is ``names[i]``; edge ``j``
    goes from ``source[j]`` to ``target[j]`` with ``weight[j]`` and type code ``kind[j]``.
    Self-loop edges of a hand-made graph are folded into ``self_returns``."""

    names: list[str]
    fitness: np.ndarray
    accepted: np.ndarray
    self_returns: np.ndarray
    source: np.ndarray
    target: np.ndarray
    weight: np.ndarray
    kind: np.ndarray
    sense: str
    fitness_tolerance: float

    @property
    def monotone(self) -> np.ndarray:
        """Mask of the MLON's edges: non-worsening, between accepted optima."""
        ok = self.accepted[self.source] & self.accepted[self.target]
        return (self.kind != WORSENING) & ok

    @property
    def best(self) -> float | None:
        """Best fitness among the accepted optima (None when there are none)."""
        return _best(self.fitness[self.accepted], self.sense)

    @property
    def sinks(self) -> np.ndarray:
        """Mask of the MLON's sinks: accepted optima without an outgoing MLON edge."""
        leaving = np.bincount(self.source[self.monotone], minlength=len(self.names))
        return self.accepted & (leaving == 0)

    def at_best(self, values: np.ndarray) -> np.ndarray:
        """Mask of ``values`` equal to the best fitness within the fitness tolerance."""
        best = self.best
        if best is None:
            return np.zeros(np.shape(values), bool)
        return np.abs(np.asarray(values) - best) <= self.fitness_tolerance


def graph_arrays(graph: nx.DiGraph) -> GraphArrays:
    """The arrays view of ``graph`` (edge types recomputed from fitness, sense, tolerance)."""
    sense = graph.graph["sense"]
    fitness_tolerance = graph.graph.get("fitness_tolerance", graph.graph.get("tolerance"))
    names = list(graph)
    n = len(names)
    index = dict(zip(names, range(n), strict=True))
    data = [d for _, d in graph.nodes(data=True)]
    fitness = np.fromiter((d["fitness"] for d in data), float, n)
    accepted = np.fromiter((d.get("accepted", True) for d in data), bool, n)
    self_returns = np.fromiter((d.get("self_returns", 0) for d in data), int, n)
    src, dst, weights = [], [], []
    for u, targets in graph.adjacency():
        src += [index[u]] * len(targets)
        dst += [index[v] for v in targets]
        weights += [d.get("weight", 1) for d in targets.values()]
    src, dst, weight = np.array(src, int), np.array(dst, int), np.array(weights, float)
    loop = src == dst
    np.add.at(self_returns, src[loop], weight[loop].astype(int))
    src, dst, weight = src[~loop], dst[~loop], weight[~loop]
    kind = edge_types(fitness[src], fitness[dst], sense, fitness_tolerance)
    return GraphArrays(
        names, fitness, accepted, self_returns, src, dst, weight, kind, sense, fitness_tolerance
    )


def best_fitness(graph: nx.DiGraph) -> float | None:
    """Best fitness among the graph's accepted optima under its sense (None when empty)."""
    data = graph.nodes(data=True)
    values = np.array([d["fitness"] for _, d in data if d.get("accepted", True)], float)
    return _best(values, graph.graph["sense"])


# ----------------------------------------------------------------------------- MLON
def mlon(graph: nx.DiGraph) -> nx.DiGraph:
    """The monotonic LON: the accepted optima and the non-worsening edges between them
    (``in_strength`` recomputed on it)."""
    out = nx.DiGraph(**graph.graph)
    out.add_nodes_from((n, d) for n, d in graph.nodes(data=True) if d.get("accepted", True))
    out.add_edges_from(
        (u, v, d)
        for u, v, d in graph.edges(data=True)
        if u in out and v in out and d["type"] != "worsening"
    )
    nx.set_node_attributes(out, dict(out.in_degree(weight="weight")), "in_strength")
    return out


def sinks(graph: nx.DiGraph) -> list[str]:
    """MLON sinks (the paper's ends of monotonic sequences): accepted optima without an
    outgoing non-worsening edge. Self-returns are no edges, so they never hide a sink."""
    arrays = graph_arrays(graph)
    return [arrays.names[i] for i in np.flatnonzero(arrays.sinks)]


# ---------------------------------------------------------------------------- CMLON
@dataclass(frozen=True)
class Compressed:
    """The CMLON as arrays. ``label[i]`` is the plateau of MLON optimum ``mlon_index[i]``;
    plateau ``k`` has ``fitness[k]`` (its members' best) and ``size[k]`` members; edges
    ``source -> target`` (all improving) carry the summed MLON ``weight``."""

    mlon_index: np.ndarray
    label: np.ndarray
    fitness: np.ndarray
    size: np.ndarray
    source: np.ndarray
    target: np.ndarray
    weight: np.ndarray
    dropped_worsening: int

    @property
    def names(self) -> list[str]:
        """Plateau names ``c0``, ``c1``, ... (ordered by their first member in graph order)."""
        return [f"c{k}" for k in range(len(self.fitness))]

    @property
    def in_strength(self) -> np.ndarray:
        """Weighted in-degree of every plateau."""
        return np.bincount(self.target, weights=self.weight, minlength=len(self.fitness))

    @property
    def funnels(self) -> np.ndarray:
        """Indices of the CMLON's sinks (plateaus without an outgoing edge)."""
        return np.flatnonzero(np.bincount(self.source, minlength=len(self.fitness)) == 0)


def compress(arrays: GraphArrays) -> Compressed:
    """Contract the MLON's equal edges to a fixpoint (see the module docstring)."""
    keep = np.flatnonzero(arrays.accepted)
    local = np.full(len(arrays.names), -1)
    local[keep] = np.arange(len(keep))
    edges = arrays.monotone
    src, dst = local[arrays.source[edges]], local[arrays.target[edges]]
    weight = arrays.weight[edges]
    label, fitness = np.arange(len(keep)), arrays.fitness[keep]
    best_of = np.maximum if arrays.sense == "max" else np.minimum
    while True:
        a, b = label[src], label[dst]
        equal = (a != b) & (np.abs(fitness[a] - fitness[b]) <= arrays.fitness_tolerance)
        if not equal.any():
            break
        k = len(fitness)
        adjacency = coo_matrix((np.ones(int(equal.sum())), (a[equal], b[equal])), shape=(k, k))
        count, plateau = connected_components(adjacency, directed=False)
        merged = np.full(count, -np.inf if arrays.sense == "max" else np.inf)
        best_of.at(merged, plateau, fitness)
        label, fitness = plateau[label], merged
    label, fitness = _renumber_by_first_member(label, fitness)
    a, b = label[src], label[dst]
    between = a != b
    k = len(fitness)
    pairs, _, inverse = _unique_pairs(a[between] * k + b[between])
    summed = np.bincount(inverse, weights=weight[between], minlength=pairs.size)
    a, b = pairs // max(k, 1), pairs % max(k, 1)
    improving = (
        edge_types(fitness[a], fitness[b], arrays.sense, arrays.fitness_tolerance) == IMPROVING
    )
    return Compressed(
        keep,
        label,
        fitness,
        np.bincount(label, minlength=k),
        a[improving],
        b[improving],
        summed[improving],
        int((~improving).sum()),
    )


def _renumber_by_first_member(
    label: np.ndarray, fitness: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Plateau numbers in order of each plateau's first member, so names are stable."""
    _, first = np.unique(label, return_index=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[label], fitness[order]


def cmlon(graph: nx.DiGraph) -> nx.DiGraph:
    """The compressed MLON (contraction to a fixpoint; see the module docstring).

    Node attributes: ``fitness`` (best member's), ``size`` (optima contracted), ``members``
    (their names, sorted), ``in_strength``, ``sink`` (a funnel) and ``best``; edges are
    ``improving`` with the summed ``weight`` of the MLON edges between the plateaus.
    ``graph.graph["dropped_worsening"]`` counts edges dropped because they ended up
    worsening between plateaus.
    """
    arrays = graph_arrays(graph)
    c = compress(arrays)
    names = c.names
    out = nx.DiGraph(
        sense=arrays.sense,
        fitness_tolerance=arrays.fitness_tolerance,
        dropped_worsening=c.dropped_worsening,
    )
    order = np.argsort(c.label, kind="stable")
    groups = (
        np.split(np.asarray(arrays.names, object)[c.mlon_index[order]], np.cumsum(c.size)[:-1])
        if len(c.label)
        else []
    )
    sink = np.zeros(len(names), bool)
    sink[c.funnels] = True
    columns = {
        "fitness": c.fitness,
        "size": c.size,
        "members": [sorted(group.tolist()) for group in groups],
        "in_strength": c.in_strength.astype(int),
        "sink": sink,
        "best": arrays.at_best(c.fitness),
    }
    edges = (
        (names[a], names[b], {"type": "improving", "weight": int(w)})
        for a, b, w in zip(c.source.tolist(), c.target.tolist(), c.weight.tolist(), strict=True)
    )
    _fill(out, names, columns, edges)
    return out
