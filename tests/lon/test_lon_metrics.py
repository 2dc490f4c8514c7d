"""LON metrics with known answers, each on its graph; per-node and per-funnel tables."""

import math
import re
from pathlib import Path

import pandas as pd
import pytest

from lonlib.lon.graphs import build_lon, node_id
from lonlib.lon.metrics import METRICS, funnel_metrics, lon_metrics, metrics_table, node_metrics
from tests.lon.test_lon import HAND, PLATEAU_GLOBAL, SELF_LOOP_ON_GLOBAL, trace_lon, trials


def test_metrics_of_the_hand_built_sample():
    m = lon_metrics(build_lon(HAND))
    assert m["optima"] == 5 and m["edges"] == 2 and m["self_returns"] == 0
    assert (m["improving"], m["equal"], m["worsening"]) == (1, 1, 0)
    assert m["sinks"] == 3 and m["global_sinks"] == 2
    assert m["funnels"] == 3 and m["global_funnels"] == 2 and m["cmlon_nodes"] == 4
    assert m["neutral"] == pytest.approx(1 - 4 / 5)
    assert m["neutral_optima"] == pytest.approx(2 / 5)
    assert m["strength_global_sinks"] == pytest.approx(1.0)
    assert m["global_strength"] == pytest.approx(1.0)
    assert m["global_funnel_proportion"] == pytest.approx(3 / 4)
    assert m["success"] == pytest.approx(2 / 3)
    assert m["deviation"] == pytest.approx(0.4 / 3)
    assert m["best"] == 0.5 and m["runs"] == 3


def test_the_full_lon_changes_only_the_lon_counts():
    m, full = lon_metrics(build_lon(HAND)), lon_metrics(build_lon(HAND, full=True))
    assert full["worsening"] == 7 and full["edges"] == 9
    lon_only = {"edges", "worsening"}
    assert {k: v for k, v in full.items() if k not in lon_only} == {
        k: v for k, v in m.items() if k not in lon_only
    }


def test_self_loop_on_the_global_optimum(tmp_path):
    m = lon_metrics(trace_lon(tmp_path, SELF_LOOP_ON_GLOBAL))
    assert m["edges"] == 3 and m["improving"] == 3 and m["self_returns"] == 4
    assert m["sinks"] == 2 and m["global_sinks"] == 1
    assert m["funnels"] == 2 and m["global_funnels"] == 1
    # into g: 2 of the 2 hops that enter a funnel, 2 of the 3 hops that enter any node
    assert m["strength_global_sinks"] == pytest.approx(1.0)
    assert m["global_strength"] == pytest.approx(2 / 3)
    assert m["global_funnel_proportion"] == pytest.approx(4 / 5)  # a, b, c, g of 5
    assert m["success"] == pytest.approx(2 / 3) and m["deviation"] == pytest.approx(5 / 3)
    assert m["best"] == 1.0 and m["runs"] == 3 and m["neutral"] == 0.0


def test_plateau_global_optimum_strength_and_funnel_share(tmp_path):
    m = lon_metrics(trace_lon(tmp_path, PLATEAU_GLOBAL))
    assert m["optima"] == 7 and m["equal"] == 2
    assert m["sinks"] == 1 and m["global_sinks"] == 0  # MLON: p <-> q never ends
    assert m["cmlon_nodes"] == 6 and m["funnels"] == 2 and m["global_funnels"] == 1
    assert m["neutral"] == pytest.approx(1 - 6 / 7)
    assert m["neutral_optima"] == pytest.approx(2 / 7)
    # CMLON in-strength: plateau {p, q} 2 (b, c), f 1 (e), b 1 (a)
    assert m["strength_global_sinks"] == pytest.approx(2 / 3)
    assert m["global_strength"] == pytest.approx(2 / 4)
    assert m["global_funnel_proportion"] == pytest.approx(4 / 6)  # a, b, c, {p, q}
    assert m["success"] == pytest.approx(2 / 3)


def test_ratios_without_a_denominator_are_nan(tmp_path):
    m = lon_metrics(trace_lon(tmp_path, "1 2.0 a 2.0 a\n"))
    assert m["optima"] == 1 and m["funnels"] == 1 and m["global_funnels"] == 1
    assert math.isnan(m["strength_global_sinks"]) and math.isnan(m["global_strength"])
    assert m["global_funnel_proportion"] == 1.0 and m["success"] == 1.0


def test_node_metrics(tmp_path):
    table = node_metrics(trace_lon(tmp_path, SELF_LOOP_ON_GLOBAL))
    assert list(table.index) == ["a", "b", "g", "c", "d"]
    assert table.loc["g"].to_dict() == {
        "fitness": 1.0,
        "in_strength": 2,
        "out_degree": 0,
        "self_returns": 3,
        "sink": True,
        "best": True,
    }
    assert list(table["out_degree"]) == [1, 1, 0, 1, 0]
    assert list(table["in_strength"]) == [0, 1, 2, 0, 0]
    assert list(table["sink"]) == [False, False, True, False, True]
    full = node_metrics(build_lon(HAND, full=True))
    assert full.loc[node_id(1e-4, 0, 0), "out_degree"] == 2  # one equal, one worsening
    assert not full.loc[node_id(1e-4, 0, 1), "sink"]  # rejected


def test_funnel_metrics(tmp_path):
    table = funnel_metrics(trace_lon(tmp_path, PLATEAU_GLOBAL))
    rows = table.set_index("size").sort_index()
    assert list(rows["fitness"]) == [2.5, 1.0]
    assert list(rows["global"]) == [False, True]
    assert list(rows["in_strength"]) == [1, 2]
    assert list(rows["basin_nodes"]) == [2, 4]  # {e, f}; {a, b, c, {p, q}}
    assert list(rows["basin_share"]) == pytest.approx([2 / 6, 4 / 6])
    assert list(rows["basin_optima"]) == [2, 5]


def test_metrics_table_has_a_row_per_p():
    table = metrics_table(pd.concat([HAND, trials([(0, 0, -1, 0.3, True)], p=1e-3)]))
    assert list(table["p"]) == [1e-4, 1e-3]
    assert list(table["optima"]) == [5, 1]


def test_every_metric_is_documented_with_its_graph():
    names = [metric.name for metric in METRICS]
    assert names == list(lon_metrics(build_lon(HAND)))
    assert {metric.graph for metric in METRICS} <= {"LON", "MLON", "CMLON", "runs"}
    readme = (Path(__file__).parents[2] / "docs" / "lon.md").read_text()
    for metric in METRICS:
        row = rf"\| `{metric.name}` \| {metric.graph} \|"
        assert re.search(row, readme), f"docs/lon.md lacks the row of {metric.name}"


def test_a_self_loop_added_by_hand_counts_as_self_returns(tmp_path):
    lon = trace_lon(tmp_path, SELF_LOOP_ON_GLOBAL)
    lon.add_edge("g", "g", type="equal", weight=2)
    assert node_metrics(lon).loc["g", "self_returns"] == 5
    m = lon_metrics(lon)
    assert m["edges"] == 3 and m["self_returns"] == 6 and m["global_sinks"] == 1
