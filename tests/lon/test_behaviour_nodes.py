"""Claim d's behaviour nodes (lonlib.lon.behaviour_space) on hand-built descriptor tables: close
behaviours with close fitness are one node, far behaviours or far fitness are not, runs
meeting at a node make it multi-inward, and the standardisation is the documented one."""

import numpy as np
import pandas as pd
import pytest

from lonlib.analysis.claims import (
    BEHAVIOUR_NODE_EPSILON,
    BEHAVIOUR_NODE_FEATURES,
    BEHAVIOUR_NODE_FITNESS_TOLERANCE,
)
from lonlib.lon.behaviour_space import (
    behaviour_features,
    behaviour_node_curve,
    behaviour_nodes,
    standardise,
)

FEATURES = BEHAVIOUR_NODE_FEATURES


def behaviour(spin: float, rods: int = 2) -> dict:
    """Descriptor columns of a behaviour placed by ``spin`` along the turns of rod 0."""
    columns = {
        "b_upright_share_0": 0.5,
        "b_turns_0": spin,
        "b_phase": 0.0 if rods == 2 else float("nan"),
        "b_cart_range": 2.0,
        "b_cart_speed": 1.5,
        "b_end_step": 2000,
        "b_nominal_steps": 2000,
    }
    if rods == 2:
        columns |= {"b_upright_share_1": 0.5, "b_turns_1": 0.0}
    return columns


def table(runs: list[list[tuple[float, float]]], rods: int = 2) -> pd.DataFrame:
    """Accepted trials of one p: per run a chain of (fitness, spin), each the parent of
    the next (index 0 the start)."""
    rows = []
    for run, chain in enumerate(runs):
        for index, (fitness, spin) in enumerate(chain):
            rows.append(
                {"p": 1e-4, "run": run, "index": index, "parent": index - 1,
                 "fitness": fitness, "accepted": True, **behaviour(spin, rods)}
            )  # fmt: skip
    return pd.DataFrame(rows)


def nodes(trials: pd.DataFrame, epsilon: float = BEHAVIOUR_NODE_EPSILON):
    return behaviour_nodes(trials, FEATURES, epsilon, BEHAVIOUR_NODE_FITNESS_TOLERANCE)


# Spins far apart in standard deviations: 0, 10, 20, 30 and one of 100 (a spread of ~38).
FAR = [0.0, 10.0, 20.0, 30.0]


def test_two_runs_reaching_the_same_behaviour_make_one_multi_inward_node():
    # two runs start apart and both reach spin 100 at fitness 0.30 (the second 0.31)
    trials = table([[(0.10, FAR[0]), (0.30, 100.0)], [(0.20, FAR[2]), (0.31, 100.0)]])
    result = nodes(trials)
    assert (result.optima, result.nodes, result.edges, result.multi_inward) == (4, 3, 2, 1)
    assert list(result.node) == [0, 1, 2, 1] and result.share == pytest.approx(1 / 3)
    assert result.self_returns == 0 and result.features == FEATURES


def test_far_behaviours_are_separate_nodes():
    trials = table([[(0.10, FAR[0]), (0.30, 100.0)], [(0.20, FAR[2]), (0.30, 60.0)]])
    result = nodes(trials)
    assert (result.nodes, result.multi_inward) == (4, 0)


def test_fitness_beyond_the_tolerance_separates_equal_behaviours():
    trials = table([[(0.10, FAR[0]), (0.30, 100.0)], [(0.20, FAR[2]), (0.3205, 100.0)]])
    assert (nodes(trials).nodes, nodes(trials).multi_inward) == (4, 0)
    # 0.02 exactly (40 steps of 2000) is within it, whatever the float rounding
    trials = table([[(0.10, FAR[0]), (0.302, 100.0)], [(0.20, FAR[2]), (0.322, 100.0)]])
    assert (nodes(trials).nodes, nodes(trials).multi_inward) == (3, 1)


def test_a_chain_of_close_optima_is_one_node_and_hops_inside_it_are_self_returns():
    # one run: spin 0 -> 1 -> 2 at equal fitness (a spread of ~4: each hop within epsilon,
    # the ends not), another run far away
    trials = table([[(0.30, 0.0), (0.30, 1.0), (0.30, 2.0)], [(0.10, 10.0)]])
    z = standardise(behaviour_features(trials.sort_values(["run", "index"]), FEATURES))
    spin = z[:, FEATURES.index("turns_0")]
    assert abs(spin[1] - spin[0]) < BEHAVIOUR_NODE_EPSILON < abs(spin[2] - spin[0])
    result = nodes(trials)
    assert (result.nodes, result.edges, result.self_returns) == (2, 0, 2)
    assert list(result.node) == [0, 0, 0, 1]


def test_one_node_entered_twice_from_one_source_node_is_not_multi_inward():
    # both runs start at one behaviour (spin 0, fitness 0.10) and reach spin 100
    trials = table([[(0.10, 0.0), (0.30, 100.0)], [(0.10, 0.0), (0.30, 100.0)]])
    result = nodes(trials)
    assert (result.nodes, result.edges, result.multi_inward) == (2, 1, 0)


def test_standardisation_zero_spread_nan_and_end_share():
    trials = table([[(0.1, 0.0), (0.2, 10.0)]])
    trials.loc[1, "b_end_step"] = 1000
    raw = behaviour_features(trials, FEATURES)
    assert list(raw.columns) == list(FEATURES)
    assert list(raw["end_share"]) == [1.0, 0.5]
    z = standardise(raw)
    assert (z[:, [0, 1, 3, 4, 5, 6]] == 0).all()  # no spread
    assert list(z[:, FEATURES.index("turns_0")]) == [-1.0, 1.0]  # population std
    assert list(z[:, FEATURES.index("end_share")]) == [1.0, -1.0]
    trials = table([[(0.1, 0.0), (0.2, 10.0), (0.3, 20.0)]])
    trials["b_phase"] = [float("nan"), -0.5, 0.5]  # a NaN in a column with spread: 0
    z = standardise(behaviour_features(trials, FEATURES))
    assert list(z[:, FEATURES.index("phase")]) == [0.0, -1.0, 1.0]
    one_cart = table([[(0.1, 0.0), (0.2, 10.0)]], rods=1)
    raw = behaviour_features(one_cart, FEATURES)
    assert "upright_share_1" not in raw and "turns_1" not in raw and raw["phase"].isna().all()
    assert np.isfinite(standardise(raw)).all()
    assert nodes(one_cart).features == tuple(raw.columns)


def test_optima_without_a_descriptor_are_nodes_of_their_own_and_none_means_untestable():
    trials = table([[(0.10, 0.0), (0.30, 100.0)], [(0.20, 20.0), (0.30, 100.0)]])
    descriptor = [c for c in trials if c.startswith("b_")]
    trials.loc[3, descriptor] = np.nan
    result = nodes(trials)
    assert (result.described, result.nodes, result.multi_inward) == (3, 4, 0)
    bare = trials.drop(columns=descriptor)
    assert nodes(bare).described == 0 and nodes(bare).nodes == 4
    assert behaviour_node_curve(bare, FEATURES, (0.5,), 0.02).empty


def test_the_curve_merges_more_as_epsilon_grows():
    trials = table([[(0.10, 0.0), (0.30, 50.0)], [(0.20, 20.0), (0.30, 60.0)]])
    curve = behaviour_node_curve(trials, FEATURES, (0.1, 0.5, 1.0, 2.0), 0.02)
    assert list(curve["nodes"]) == sorted(curve["nodes"], reverse=True)
    assert curve["nodes"].iloc[0] == 4 and curve["nodes"].iloc[-1] == 3
    assert curve["multi_inward"].iloc[-1] == 1
