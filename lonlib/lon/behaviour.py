"""The behavioural LON: optima with the same behaviour and equal fitness as one node.

A neutral-network view of "same behaviour, different weights" (README, "Behaviours"):
accepted optima of one p with the same label (:mod:`lonlib.task.behaviour`) whose fitness values
are equal within the LON's fitness tolerance (``fitness_tolerance``; chained: sorted values
closer than it to their neighbour join, as the CMLON's contraction chains equal edges)
become one node, and so do rejected optima among themselves; optima without a label are never
merged. A transition between two members of one node becomes a self-return of that node;
transitions between nodes are summed. The result is a LON graph like
:func:`lonlib.lon.graphs.build_lon`'s, so every metric of :mod:`lonlib.lon.metrics`, the MLON and
the CMLON apply to it unchanged.
"""

from __future__ import annotations

import networkx as nx
import numpy as np
import pandas as pd

from lonlib.lon.graphs import Transitions, assemble_lon, build_lon, graph_arrays, node_id, sinks


def behaviour_groups(graph: nx.DiGraph) -> pd.Series:
    """Node name -> group name (``<label> @ <fitness> #<k>``, prefixed ``rejected`` for
    rejected optima): the nodes the behavioural LON contracts together."""
    arrays = graph_arrays(graph)
    table = pd.DataFrame(
        {
            "name": arrays.names,
            "label": [graph.nodes[n].get("label", "") or "unlabelled" for n in arrays.names],
            "p": [graph.nodes[n].get("p", 0.0) for n in arrays.names],
            "fitness": arrays.fitness,
            "accepted": arrays.accepted,
        }
    ).sort_values(["p", "accepted", "label", "fitness"], kind="stable")
    same_kind = (
        (table["accepted"] == table["accepted"].shift())
        & (table["label"] == table["label"].shift())
        & (table["p"] == table["p"].shift())
        & (table["label"] != "unlabelled")  # optima without a descriptor are never merged
    )
    close = table["fitness"].diff().abs() <= arrays.fitness_tolerance
    group = (~(same_kind & close)).cumsum()
    best = table.groupby(group)["fitness"].transform("max" if arrays.sense == "max" else "min")
    prefix = np.where(table["accepted"], "", "rejected ")
    names = [
        f"{pre}{lab} @ {fit:.4g} #{k}"
        for pre, lab, fit, k in zip(prefix, table["label"], best, group, strict=True)
    ]
    return pd.Series(names, index=table["name"]).reindex(arrays.names)


def behavioural_lon(graph: nx.DiGraph) -> nx.DiGraph:
    """The behavioural LON of a LON (see the module docstring). Node attributes: ``label``,
    ``fitness`` (the members' best), ``size``, ``members``, ``accepted``, ``start`` (any
    member a start), and the LON annotations (``self_returns``, ``in_strength``, ``sink``,
    ``best``)."""
    arrays = graph_arrays(graph)
    groups = behaviour_groups(graph)
    names = list(dict.fromkeys(groups))
    index = pd.Index(names)
    member_group = index.get_indexer(groups.to_numpy())
    n = len(names)
    best_of = np.maximum if arrays.sense == "max" else np.minimum
    fitness = np.full(n, -np.inf if arrays.sense == "max" else np.inf)
    best_of.at(fitness, member_group, arrays.fitness)
    accepted = np.zeros(n, bool)
    accepted[member_group] = arrays.accepted
    start = np.zeros(n, bool)
    np.logical_or.at(
        start, member_group, [graph.nodes[m].get("start", False) for m in groups.index]
    )
    members = [sorted(groups.index[member_group == k]) for k in range(n)]
    labels = [graph.nodes[m[0]].get("label", "") or "unlabelled" for m in members]
    # Hops of the contracted graph: every edge repeated by its weight, member self-returns
    # as hops from a node to itself (so assemble_lon counts them as self-returns).
    weight = arrays.weight.astype(int)
    src = np.concatenate(
        [np.repeat(member_group[arrays.source], weight), member_group.repeat(arrays.self_returns)]
    )
    dst = np.concatenate(
        [np.repeat(member_group[arrays.target], weight), member_group.repeat(arrays.self_returns)]
    )
    runs = np.full(src.size, "", dtype=object)
    hops = Transitions(src, dst, runs, np.arange(src.size))
    run_ends = {key: groups[end] for key, end in graph.graph.get("run_ends", {}).items()}
    nodes = {
        "fitness": fitness,
        "accepted": accepted,
        "start": start,
        "label": np.array(labels, object),
        "size": np.bincount(member_group, minlength=n),
        "members": members,
    }
    out = assemble_lon(names, nodes, hops, run_ends, arrays.sense, arrays.fitness_tolerance)
    out.graph["behavioural"] = True
    return out


def behaviour_table(trials: pd.DataFrame, fitness_tolerance: float = 1e-9) -> pd.DataFrame:
    """The "typical behaviours" table: per p and label, the accepted optima, the sinks
    (ends of monotonic sequences, on the MLON), their fitness range and the label's share
    of all sinks at that p. Rows are sorted by p, then by best fitness (descending)."""
    if "label" not in trials:
        raise ValueError("trials carry no behaviour labels (no 'label' column)")
    rows = []
    for p, group in trials.groupby("p", sort=True):
        graph = build_lon(group, sense="max", fitness_tolerance=fitness_tolerance)
        sink_set = set(sinks(graph))
        accepted = group[group["accepted"].astype(bool)].fillna({"label": "unlabelled"})
        names = [node_id(p, r, i) for r, i in zip(accepted["run"], accepted["index"], strict=True)]
        is_sink = pd.Series([name in sink_set for name in names], index=accepted.index)
        for label, members in accepted.groupby("label", sort=False):
            fitness = members["fitness"]
            rows.append(
                {
                    "p": p,
                    "label": label,
                    "optima": len(members),
                    "sinks": int(is_sink[members.index].sum()),
                    "fitness_min": fitness.min(),
                    "fitness_max": fitness.max(),
                    "sink_share": is_sink[members.index].sum() / max(len(sink_set), 1),
                }
            )
    table = pd.DataFrame(rows)
    if table.empty:
        return table
    return table.sort_values(["p", "fitness_max"], ascending=[True, False], ignore_index=True)
