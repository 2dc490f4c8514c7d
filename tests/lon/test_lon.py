"""LON, MLON and CMLON on hand-built trials and traces with known answers."""

import warnings

import pandas as pd
import pytest

from lonlib.lon.graphs import (
    FitnessSpreadWarning,
    build_lon,
    cmlon,
    edge_type,
    lon_from_transitions,
    mlon,
    node_id,
    sinks,
)
from lonlib.lon.io import from_trace


def trials(rows, p=1e-4):
    """rows: (run, index, parent, fitness, accepted)."""
    return pd.DataFrame(
        [
            {
                "p": p,
                "run": r,
                "index": i,
                "parent": par,
                "fitness": f,
                "accepted": a,
                "seconds": 0.0,
                "env_steps": 0,
            }
            for r, i, par, f, a in rows
        ]
    )


HAND = trials(
    [
        (0, 0, -1, 0.2, True),
        (0, 1, 0, 0.1, False),
        (0, 2, 0, 0.2, True),
        (0, 3, 2, 0.5, True),
        (0, 4, 3, 0.3, False),
        (0, 5, 3, 0.4, False),
        (1, 0, -1, 0.5, True),
        (1, 1, 0, 0.4, False),
        (1, 2, 0, 0.4, False),
        (2, 0, -1, 0.1, True),
        (2, 1, 0, 0.05, False),
        (2, 2, 0, 0.0, False),
    ]
)

# Minimised traces, one row a hop: "run fit1 node1 fit2 node2".
SELF_LOOP_ON_GLOBAL = """\
1 5.0 a 3.0 b
1 3.0 b 1.0 g
1 1.0 g 1.0 g
1 1.0 g 1.0 g
2 4.0 c 1.0 g
2 1.0 g 1.0 g
3 6.0 d 6.0 d
"""
PLATEAU_GLOBAL = """\
1 5.0 a 2.0 b
1 2.0 b 1.0 p
1 1.0 p 1.0 q
1 1.0 q 1.0 p
2 3.0 c 1.0 q
3 4.0 e 2.5 f
"""
NOISY_NODE = """\
1 5.0 a 3.0 b
1 3.00000001 b 1.0 c
2 4.0 d 2.99999998 b
2 3.0 b 3.0 e
"""
# With tolerance 1: w~x merge (9.3), then x->y becomes equal (8.6), then x->z (7.9).
NEAR_EQUAL_CHAIN = """\
1 9.3 w 10.0 x
1 10.0 x 8.6 y
2 10.0 x 7.9 z
2 7.9 z 5.0 q
"""


def write_trace(tmp_path, rows, name="t.trace"):
    path = tmp_path / name
    path.write_text("run fit1 node1 fit2 node2\n" + rows)
    return path


def trace_lon(tmp_path, rows, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("error", FitnessSpreadWarning)  # only NOISY_NODE is noisy
        return from_trace(write_trace(tmp_path, rows), **kwargs)


def test_paper_lon_of_a_hand_built_sample():
    lon = build_lon(HAND)
    assert set(lon) == {
        node_id(1e-4, 0, 0),
        node_id(1e-4, 0, 2),
        node_id(1e-4, 0, 3),
        node_id(1e-4, 1, 0),
        node_id(1e-4, 2, 0),
    }
    assert lon.edges[node_id(1e-4, 0, 0), node_id(1e-4, 0, 2)]["type"] == "equal"
    assert lon.edges[node_id(1e-4, 0, 2), node_id(1e-4, 0, 3)]["type"] == "improving"
    assert sorted(sinks(lon)) == sorted(
        [node_id(1e-4, 0, 3), node_id(1e-4, 1, 0), node_id(1e-4, 2, 0)]
    )
    assert {n for n, d in lon.nodes(data=True) if d["sink"]} == set(sinks(lon))
    starts = {n for n, s in lon.nodes(data="start") if s}
    assert starts == {node_id(1e-4, r, 0) for r in range(3)}
    assert lon.nodes[node_id(1e-4, 0, 3)]["best"] and lon.nodes[node_id(1e-4, 1, 0)]["best"]
    assert not lon.nodes[node_id(1e-4, 0, 2)]["best"]
    assert lon.graph["run_ends"] == {
        "0.0001:0": node_id(1e-4, 0, 3),
        "0.0001:1": node_id(1e-4, 1, 0),
        "0.0001:2": node_id(1e-4, 2, 0),
    }


def test_full_lon_adds_rejected_optima_behind_worsening_edges():
    full = build_lon(HAND, full=True)
    assert full.number_of_nodes() == 12
    assert sum(t == "worsening" for _, _, t in full.edges(data="type")) == 7
    assert full.nodes[node_id(1e-4, 0, 4)]["sink"] is False  # a rejected optimum is no sink
    assert full.nodes[node_id(1e-4, 0, 3)]["sink"] is True  # worsening edges do not count
    assert full.nodes[node_id(1e-4, 0, 0)]["in_strength"] == 0
    assert full.nodes[node_id(1e-4, 0, 3)]["in_strength"] == 1
    monotone = mlon(full)
    assert set(monotone) == set(build_lon(HAND))
    assert all(t != "worsening" for _, _, t in monotone.edges(data="type"))


def test_a_trial_whose_parent_is_missing_is_refused():
    with pytest.raises(ValueError, match="parent"):
        build_lon(trials([(0, 1, 0, 0.5, True)]))


def test_cmlon_contracts_equal_plateaus():
    compressed = cmlon(build_lon(HAND))
    assert compressed.number_of_nodes() == 4
    sizes = sorted(compressed.nodes[n]["size"] for n in compressed)
    assert sizes == [1, 1, 1, 2]
    plateau = next(n for n in compressed if compressed.nodes[n]["size"] == 2)
    assert compressed.nodes[plateau]["members"] == [node_id(1e-4, 0, 0), node_id(1e-4, 0, 2)]
    assert all(t == "improving" for _, _, t in compressed.edges(data="type"))


def test_sense_and_tolerance_are_explicit():
    assert edge_type(1.0, 2.0, "max", 0.0) == "improving"
    assert edge_type(1.0, 2.0, "min", 0.0) == "worsening"
    assert edge_type(1.0, 1.05, "max", 0.1) == "equal"
    assert edge_type(1.0, 1.0, "min", 0.0) == "equal"
    assert edge_type(1.0, 1.05, "max", 0.01) == "improving"
    minimised = build_lon(HAND, sense="min")
    assert minimised.nodes[node_id(1e-4, 2, 0)]["best"]
    with pytest.raises(ValueError, match="sense"):
        build_lon(HAND, sense="up")
    with pytest.raises(ValueError, match="fitness_tolerance"):
        build_lon(HAND, fitness_tolerance=-1.0)


# ------------------------------------------------------------------ issue 9, point by point
def test_a_self_return_is_counted_never_an_edge(tmp_path):
    lon = trace_lon(tmp_path, SELF_LOOP_ON_GLOBAL)
    assert not any(u == v for u, v in lon.edges)
    assert set(lon.edges) == {("a", "b"), ("b", "g"), ("c", "g")}
    assert lon.nodes["g"]["self_returns"] == 3
    assert lon.nodes["d"]["self_returns"] == 1
    assert lon.nodes["a"]["self_returns"] == 0
    # The global optimum stays a sink, and so does a node whose only moves return to itself.
    assert sorted(sinks(lon)) == ["d", "g"]
    assert lon.nodes["g"]["sink"] and lon.nodes["d"]["sink"] and lon.nodes["g"]["best"]
    assert lon.nodes["g"]["in_strength"] == 2
    assert lon.graph["run_ends"] == {"1": "g", "2": "g", "3": "d"}
    assert {n for n, s in lon.nodes(data="start") if s} == {"a", "c", "d"}
    assert sorted(cmlon(lon)) == ["c0", "c1", "c2", "c3", "c4"]


def test_a_plateau_global_optimum_is_one_cmlon_funnel(tmp_path):
    lon = trace_lon(tmp_path, PLATEAU_GLOBAL)
    assert lon.edges["p", "q"]["type"] == "equal" and lon.edges["q", "p"]["type"] == "equal"
    assert sinks(lon) == ["f"]  # the MLON has no sink on the p <-> q plateau
    compressed = cmlon(lon)
    funnels = {n for n in compressed if compressed.out_degree(n) == 0}
    by_members = {tuple(compressed.nodes[n]["members"]): n for n in compressed}
    plateau = by_members["p", "q"]
    assert funnels == {plateau, by_members["f",]}
    assert compressed.nodes[plateau]["fitness"] == 1.0 and compressed.nodes[plateau]["best"]
    assert compressed.nodes[plateau]["in_strength"] == 2


def test_a_noisy_node_takes_its_best_value_and_warns_with_the_spread(tmp_path):
    path = write_trace(tmp_path, NOISY_NODE)
    with pytest.warns(FitnessSpreadWarning, match=r"1 node.*spread is 3e-08 \(node b\)"):
        lon = from_trace(path)
    assert lon.nodes["b"]["fitness"] == 2.99999998  # min: the best when minimising
    with pytest.warns(FitnessSpreadWarning, match="keeps its max"):
        assert from_trace(path, sense="max").nodes["b"]["fitness"] == 3.00000001
    # The equal-edge tolerance is a parameter of its own: b (2.99999998) -> e (3.0).
    with pytest.warns(FitnessSpreadWarning):
        assert from_trace(path, fitness_tolerance=1e-9).edges["b", "e"]["type"] == "worsening"
    with pytest.warns(FitnessSpreadWarning):
        assert from_trace(path, fitness_tolerance=1e-6).edges["b", "e"]["type"] == "equal"
    # Refused only beyond the user's bound on the spread, whatever the tolerance.
    with pytest.warns(FitnessSpreadWarning):
        from_trace(path, fitness_tolerance=0.0, max_fitness_spread=3.1e-8)
    with pytest.raises(ValueError, match=r"3e-08.*max_fitness_spread=2e-08"):
        from_trace(path, fitness_tolerance=1.0, max_fitness_spread=2e-8)
    with pytest.raises(ValueError, match="max_fitness_spread"):
        from_trace(path, max_fitness_spread=-1.0)


def test_a_clean_trace_does_not_warn(tmp_path):
    trace_lon(tmp_path, PLATEAU_GLOBAL)  # FitnessSpreadWarning is an error inside


def test_contraction_reaches_a_fixpoint(tmp_path):
    lon = trace_lon(tmp_path, NEAR_EQUAL_CHAIN, fitness_tolerance=1.0)
    assert lon.edges["x", "y"]["type"] == "improving"  # 1.4 apart before any contraction
    compressed = cmlon(lon)
    assert sorted(compressed.nodes[n]["members"] for n in compressed) == [["q"], list("wxyz")]
    plateau = next(n for n in compressed if compressed.nodes[n]["size"] == 4)
    assert compressed.nodes[plateau]["fitness"] == 7.9
    assert [(compressed.nodes[u]["size"], d) for u, _, d in compressed.edges(data="weight")] == [
        (4, 1)
    ]


def test_an_edge_that_ends_up_worsening_between_plateaus_is_dropped(tmp_path):
    rows = "1 1.0 a 1.9 b\n1 1.9 b 2.8 c\n1 2.8 c 3.7 d\n1 3.7 d 2.5 y\n"
    compressed = cmlon(trace_lon(tmp_path, rows, fitness_tolerance=1.0))
    assert compressed.graph["dropped_worsening"] == 1
    assert compressed.number_of_edges() == 0
    assert sorted(compressed.nodes[n]["members"] for n in compressed) == [list("abcd"), ["y"]]


def test_transitions_from_a_table_and_its_checks():
    table = pd.DataFrame(
        {"run": [1, 1], "fit1": [2.0, 1.0], "node1": ["a", "b"], "fit2": [1.0, 1.0],
         "node2": ["b", "b"]}
    )  # fmt: skip
    lon = lon_from_transitions(table)
    assert set(lon.edges) == {("a", "b")} and lon.nodes["b"]["self_returns"] == 1
    assert lon.graph["run_ends"] == {"1": "b"}
    with pytest.raises(ValueError, match="missing columns"):
        lon_from_transitions(table.drop(columns="fit2"))
    empty = lon_from_transitions(table.iloc[:0])
    assert empty.number_of_nodes() == 0 and empty.graph["run_ends"] == {}


def test_worsening_rows_leave_their_target_unaccepted(tmp_path):
    lon = trace_lon(tmp_path, "1 1.0 a 2.0 r\n1 1.0 a 0.5 b\n")
    assert lon.edges["a", "r"]["type"] == "worsening"
    assert not lon.nodes["r"]["accepted"] and not lon.nodes["r"]["sink"]
    assert lon.nodes["b"]["accepted"] and lon.graph["run_ends"] == {"1": "b"}
    assert set(mlon(lon)) == {"a", "b"}
