"""LON construction and metrics on hand-built trials with known answers; trace and GraphML."""

import networkx as nx
import pandas as pd
import pytest

from lonlib.lon import (
    build_lon,
    cmlon,
    edge_type,
    from_trace,
    lon_metrics,
    metrics_table,
    node_id,
    sinks,
    to_graphml,
    to_igraph,
    to_trace,
)


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
    starts = {n for n, s in lon.nodes(data="start") if s}
    assert starts == {node_id(1e-4, r, 0) for r in range(3)}
    assert lon.nodes[node_id(1e-4, 0, 3)]["best"] and lon.nodes[node_id(1e-4, 1, 0)]["best"]


def test_metrics_with_known_answers():
    m = lon_metrics(build_lon(HAND))
    assert m["optima"] == 5 and m["edges"] == 2
    assert (m["improving"], m["equal"], m["worsening"]) == (1, 1, 0)
    assert m["sinks"] == 3 and m["global_sinks"] == 2 and m["funnels"] == 3
    assert m["neutral"] == pytest.approx(1 - 4 / 5)
    assert m["strength_global_sinks"] == pytest.approx(0.5)
    assert m["global_funnel_proportion"] == pytest.approx(4 / 5)
    assert m["success"] == pytest.approx(2 / 3)
    assert m["deviation"] == pytest.approx(0.4 / 3)
    assert m["best"] == 0.5 and m["runs"] == 3


def test_full_lon_adds_worsening_edges_from_rejected_trials():
    full = build_lon(HAND, full=True)
    m = lon_metrics(full)
    assert m["worsening"] == 7 and m["edges"] == 9
    assert m["optima"] == 5  # the MLON part is unchanged
    assert m["sinks"] == 3
    assert full.nodes[node_id(1e-4, 0, 4)]["sink"] is False  # a rejected optimum is no sink


def test_cmlon_contracts_equal_plateaus():
    compressed = cmlon(build_lon(HAND))
    assert compressed.number_of_nodes() == 4
    sizes = sorted(compressed.nodes[n]["size"] for n in compressed)
    assert sizes == [1, 1, 1, 2]


def test_sense_and_tolerance_are_explicit():
    assert edge_type(1.0, 2.0, "max", 0.0) == "improving"
    assert edge_type(1.0, 2.0, "min", 0.0) == "worsening"
    assert edge_type(1.0, 1.05, "max", 0.1) == "equal"
    minimised = build_lon(HAND, sense="min")
    assert lon_metrics(minimised)["best"] == 0.1
    with pytest.raises(ValueError, match="sense"):
        build_lon(HAND, sense="up")
    with pytest.raises(ValueError, match="tolerance"):
        build_lon(HAND, tolerance=-1.0)


def test_trace_export_then_import_gives_the_same_network(tmp_path):
    lon = build_lon(HAND, full=True)
    path = tmp_path / "lon.trace"
    to_trace(lon, path)
    assert path.read_text().splitlines()[0] == "run fit1 node1 fit2 node2"
    back = from_trace(path, sense="max")
    connected = {n for e in lon.edges for n in e}
    assert set(back) == connected
    for u, v, data in lon.edges(data=True):
        assert back.edges[u, v]["type"] == data["type"]
        assert back.edges[u, v]["weight"] == data["weight"]
    for n in back:
        assert back.nodes[n]["fitness"] == lon.nodes[n]["fitness"]


def test_trace_from_another_tool_minimising(tmp_path):
    path = tmp_path / "other.trace"
    path.write_text("run fit1 node1 fit2 node2\n1 5.0 a 3.0 b\n1 3.0 b 3.0 c\n2 4.0 d 3.0 b\n")
    lon = from_trace(path)  # minimisation by default
    assert lon.graph["sense"] == "min"
    assert lon.edges["a", "b"]["type"] == "improving" and lon.edges["b", "c"]["type"] == "equal"
    m = lon_metrics(lon)
    assert m["optima"] == 4 and m["best"] == 3.0 and m["sinks"] == 1
    assert lon.nodes["b"]["in_strength"] == 2
    bad = tmp_path / "bad.trace"
    bad.write_text("a b c\n")
    with pytest.raises(ValueError, match="bad.trace"):
        from_trace(bad)


def test_graphml_networkx_and_igraph(tmp_path):
    lon = build_lon(HAND, full=True)
    to_graphml(lon, tmp_path / "lon.graphml")
    back = nx.read_graphml(tmp_path / "lon.graphml")
    assert back.number_of_nodes() == lon.number_of_nodes()
    assert back.number_of_edges() == lon.number_of_edges()
    g = to_igraph(lon)
    assert g.vcount() == lon.number_of_nodes() and g.ecount() == lon.number_of_edges()
    assert g.is_directed()


def test_metrics_table_has_a_row_per_p():
    table = metrics_table(pd.concat([HAND, trials([(0, 0, -1, 0.3, True)], p=1e-3)]))
    assert list(table["p"]) == [1e-4, 1e-3]
    assert list(table["optima"]) == [5, 1]
