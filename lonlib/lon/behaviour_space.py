"""Nodes in behaviour space: accepted optima of one p whose behaviour and fitness are close,
as one node, and how many of those nodes several runs' transitions lead into (claim d).

A parameter-level LON (:func:`lonlib.lon.graphs.build_lon`) gives every accepted optimum a node of
its own, reached by one transition, so "nodes are never visited by several inward edges"
holds there by construction. Here a node is a class of optima that *behave* alike:

1. **Features** (:func:`behaviour_features`): the descriptor columns ``b_<feature>`` of the
   trials for each name in ``features`` (``end_share`` = ``b_end_step`` /
   ``b_nominal_steps``); names whose column is absent (one cart: the second rod's) are left
   out, so one-cart data use rod 0's features.
2. **Standardised** (:func:`standardise`) over the accepted optima of one p: each column
   z-scored (mean and population standard deviation, NaN ignored); a column without spread
   contributes 0; a NaN (the phase of one rod) becomes 0.
3. **Graph**: two optima are joined when their standardised features lie within
   ``epsilon`` (Euclidean) *and* their fitness differs by at most ``fitness_tolerance`` (plus 1e-9
   for float rounding: fitness is a count of steps over the nominal steps). An optimum
   without a descriptor is joined to nothing.
4. **Nodes**: the connected components of that graph (a transitive closure: a chain of close
   optima is one node even when its ends are far apart).

The LON's accepted transitions (trial ``parent`` -> trial, within a run) are mapped onto the
nodes; a transition inside one node is a self-return, not an edge. A node is *multi-inward*
when edges from at least two distinct other nodes lead into it: runs (or one run's chain
from two places) converge there.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

PREFIX = "b_"
FITNESS_SLACK = 1e-9
"""Added to the fitness tolerance: fitness values are step counts over the nominal steps,
and 0.322 - 0.302 is 0.020000000000000018 in floating point."""


def behaviour_features(trials: pd.DataFrame, features: Sequence[str]) -> pd.DataFrame:
    """The raw behaviour features of ``trials`` (one column per name in ``features`` whose
    descriptor column exists; ``end_share`` from the end step and the nominal steps), float,
    in the rows' order. No column at all when the trials carry no descriptor."""
    columns = {}
    for name in features:
        if name == "end_share":
            if {f"{PREFIX}end_step", f"{PREFIX}nominal_steps"} <= set(trials.columns):
                end = trials[f"{PREFIX}end_step"].astype(float)
                columns[name] = end / trials[f"{PREFIX}nominal_steps"].astype(float)
        elif f"{PREFIX}{name}" in trials:
            columns[name] = trials[f"{PREFIX}{name}"].astype(float)
    return pd.DataFrame(columns, index=trials.index)


def standardise(features: pd.DataFrame) -> np.ndarray:
    """Each column z-scored over the rows (mean and population standard deviation of its
    finite values); a column with zero spread, and every NaN, becomes 0."""
    values = features.to_numpy(float, copy=True)
    if values.size == 0:
        return values
    finite = np.isfinite(values)
    with warnings.catch_warnings():  # a column without a finite value: NaN, then 0
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(np.where(finite, values, np.nan), axis=0)
        std = np.nanstd(np.where(finite, values, np.nan), axis=0)
    spread = np.isfinite(std) & (std > 0)
    z = np.zeros_like(values)
    z[:, spread] = (values[:, spread] - mean[spread]) / std[spread]
    z[~finite] = 0.0
    return z


def cluster(
    points: np.ndarray,
    fitness: np.ndarray,
    described: np.ndarray,
    epsilon: float,
    fitness_tolerance: float,
) -> np.ndarray:
    """Node number of each row: connected components of the graph that joins two described
    rows within ``epsilon`` (Euclidean over ``points``) and ``fitness_tolerance`` (fitness).
    Numbered by first member, so the result does not depend on the component algorithm."""
    n = len(fitness)
    if n == 0:
        return np.zeros(0, int)
    distance = np.sqrt(((points[:, None, :] - points[None, :, :]) ** 2).sum(axis=-1))
    close = np.abs(fitness[:, None] - fitness[None, :]) <= fitness_tolerance + FITNESS_SLACK
    joined = (distance <= epsilon) & close & described[:, None] & described[None, :]
    rows, cols = np.nonzero(np.triu(joined, k=1))
    graph = coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    _, first = np.unique(component, return_index=True)
    order = np.empty(len(first), int)
    order[np.argsort(first)] = np.arange(len(first))  # renumber by first member
    return order[component]


@dataclass(frozen=True)
class BehaviourNodes:
    """Claim d's numbers for one p at one ``epsilon``: ``optima`` (accepted optima),
    ``described`` (those with a descriptor), ``nodes``, ``edges`` (distinct node pairs),
    ``transitions`` (accepted transitions) of which ``self_returns`` stay inside a node,
    ``multi_inward`` (nodes with edges from >= 2 distinct nodes) and ``share`` of nodes;
    ``node`` gives each optimum's node (in the order of the accepted trials)."""

    epsilon: float
    fitness_tolerance: float
    optima: int
    described: int
    features: tuple[str, ...]
    nodes: int
    edges: int
    transitions: int
    self_returns: int
    multi_inward: int
    node: np.ndarray

    @property
    def share(self) -> float:
        """Share of the nodes that are multi-inward (NaN without nodes)."""
        return self.multi_inward / self.nodes if self.nodes else float("nan")


def accepted_optima(trials: pd.DataFrame) -> pd.DataFrame:
    """The accepted trials of one p (the LON's nodes), in run and index order."""
    rows = trials[trials["accepted"].to_numpy(bool)]
    return rows.sort_values(["run", "index"], kind="stable")


def transitions(optima: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """Positions (in ``optima``) of the source and target of each accepted transition: a
    trial's parent -> the trial, within its run (the LON's edges, one per acceptance)."""
    position = {key: i for i, key in enumerate(zip(optima["run"], optima["index"], strict=True))}
    parent = optima["parent"].to_numpy(int)
    child = np.flatnonzero(parent >= 0)
    run = optima["run"].to_numpy()
    source = np.array([position[(run[i], parent[i])] for i in child], int)
    return source, child


def behaviour_nodes(
    trials: pd.DataFrame, features: Sequence[str], epsilon: float, fitness_tolerance: float
) -> BehaviourNodes:
    """Behaviour nodes of the accepted optima of ``trials`` (one p; see the module
    docstring) and their in-edges."""
    optima = accepted_optima(trials)
    raw = behaviour_features(optima, features)
    described = raw.notna().any(axis=1).to_numpy() if raw.shape[1] else np.zeros(len(optima), bool)
    points = standardise(raw[described]) if raw.shape[1] else np.zeros((0, 0))
    full = np.zeros((len(optima), raw.shape[1]))
    full[described] = points
    fitness = optima["fitness"].to_numpy(float)
    node = cluster(full, fitness, described, epsilon, fitness_tolerance)
    source, target = transitions(optima)
    a, b = node[source], node[target]
    between = a != b
    pairs = np.unique(np.stack([a[between], b[between]], axis=1), axis=0)
    sources_per_node = np.bincount(pairs[:, 1], minlength=node.max(initial=-1) + 1)
    return BehaviourNodes(
        epsilon=float(epsilon),
        fitness_tolerance=float(fitness_tolerance),
        optima=len(optima),
        described=int(described.sum()),
        features=tuple(raw.columns),
        nodes=int(node.max(initial=-1) + 1),
        edges=len(pairs),
        transitions=len(source),
        self_returns=int((~between).sum()),
        multi_inward=int((sources_per_node > 1).sum()),
        node=node,
    )


def behaviour_node_curve(
    trials: pd.DataFrame,
    features: Sequence[str],
    epsilons: Sequence[float],
    fitness_tolerance: float,
) -> pd.DataFrame:
    """Per p and ``epsilon``: optima, nodes, edges, self-returns, multi-inward nodes and
    their share (one row each; empty when no trial carries a descriptor)."""
    rows = []
    for p, group in trials.groupby("p", sort=True):
        for epsilon in epsilons:
            result = behaviour_nodes(group, features, epsilon, fitness_tolerance)
            if not result.described:
                continue
            rows.append(
                {
                    "p": float(p),
                    "epsilon": float(epsilon),
                    "fitness_tolerance": float(fitness_tolerance),
                    "optima": result.optima,
                    "nodes": result.nodes,
                    "edges": result.edges,
                    "self_returns": result.self_returns,
                    "multi_inward": result.multi_inward,
                    "share": result.share,
                }
            )
    return pd.DataFrame(
        rows,
        columns=[
            "p",
            "epsilon",
            "fitness_tolerance",
            "optima",
            "nodes",
            "edges",
            "self_returns",
            "multi_inward",
            "share",
        ],
    )
