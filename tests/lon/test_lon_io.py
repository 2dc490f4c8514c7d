"""Trace files (both ways, and other tools' files), GraphML, igraph."""

import networkx as nx
import pytest

from lonlib.lon.graphs import build_lon, cmlon
from lonlib.lon.io import from_trace, read_trace, to_graphml, to_igraph, to_trace
from lonlib.lon.metrics import lon_metrics
from tests.lon.test_lon import (
    HAND,
    PLATEAU_GLOBAL,
    SELF_LOOP_ON_GLOBAL,
    trace_lon,
    trials,
    write_trace,
)


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
        assert back.nodes[n]["accepted"] == lon.nodes[n]["accepted"]
        assert back.nodes[n]["start"] == lon.nodes[n]["start"]
    assert back.graph["run_ends"] == lon.graph["run_ends"]  # run 1 only failed: ends at start


def test_a_long_run_keeps_its_order_through_a_trace(tmp_path):
    rows = [(0, 0, -1, 0.0, True)] + [(0, i, i - 1, i / 100, True) for i in range(1, 13)]
    lon = build_lon(trials(rows))
    to_trace(lon, tmp_path / "long.trace")
    back = from_trace(tmp_path / "long.trace", sense="max")
    assert back.graph["run_ends"] == lon.graph["run_ends"]  # t12, not t9 (text order)


@pytest.mark.parametrize("rows", [SELF_LOOP_ON_GLOBAL, PLATEAU_GLOBAL])
def test_other_tools_traces_round_trip_with_their_self_returns(tmp_path, rows):
    lon = trace_lon(tmp_path, rows)
    to_trace(lon, tmp_path / "again.trace")
    back = from_trace(tmp_path / "again.trace")
    assert dict(back.nodes(data="self_returns")) == dict(lon.nodes(data="self_returns"))
    assert {e: (d["type"], d["weight"]) for e, d in back.edges.items()} == {
        e: (d["type"], d["weight"]) for e, d in lon.edges.items()
    }
    assert lon_metrics(back) == lon_metrics(lon)
    assert back.graph["run_ends"] == lon.graph["run_ends"]


def test_trace_from_another_tool_minimising(tmp_path):
    path = write_trace(tmp_path, "1 5.0 a 3.0 b\n1 3.0 b 3.0 c\n\n2\t4.0  d 3.0 b\n")
    lon = from_trace(path)  # minimisation by default; blank lines and any white space
    assert lon.graph["sense"] == "min"
    assert lon.edges["a", "b"]["type"] == "improving" and lon.edges["b", "c"]["type"] == "equal"
    m = lon_metrics(lon)
    assert m["optima"] == 4 and m["best"] == 3.0 and m["sinks"] == 1
    assert lon.nodes["b"]["in_strength"] == 2
    table = read_trace(path)
    assert list(table.columns) == ["run", "fit1", "node1", "fit2", "node2"]
    assert list(table["node1"]) == ["a", "b", "d"] and list(table["fit2"]) == [3.0, 3.0, 3.0]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("a b c\n", "first line must be the header"),
        ("", "first line must be the header"),
        ("run fit1 node1 fit2 node2\n1 1.0 a 2.0 b\n1 2.0 b 3.0\n", r"bad.trace:3: expected 5"),
        ("run fit1 node1 fit2 node2\n\n1 1.0 a x b\n", r"bad.trace:3: .*finite numbers"),
        ("run fit1 node1 fit2 node2\n1 1.0 a 1.0 b\n1 1.0 b nan c\n", r"bad.trace:3: .*finite"),
    ],
)
def test_a_malformed_trace_is_refused_with_its_line(tmp_path, text, message):
    bad = tmp_path / "bad.trace"
    bad.write_text(text)
    with pytest.raises(ValueError, match=message):
        from_trace(bad)


def test_a_missing_trace_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="cannot read"):
        from_trace(tmp_path / "absent.trace")


def test_graphml_networkx_and_igraph(tmp_path):
    lon = build_lon(HAND, full=True)
    to_graphml(lon, tmp_path / "lon.graphml")
    back = nx.read_graphml(tmp_path / "lon.graphml")
    assert back.number_of_nodes() == lon.number_of_nodes()
    assert back.number_of_edges() == lon.number_of_edges()
    to_graphml(cmlon(lon), tmp_path / "cmlon.graphml")
    assert nx.read_graphml(tmp_path / "cmlon.graphml").number_of_nodes() == 4
    g = to_igraph(lon)
    assert g.vcount() == lon.number_of_nodes() and g.ecount() == lon.number_of_edges()
    assert g.is_directed()
