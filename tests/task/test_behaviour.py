"""Behaviour descriptors and labels: policies of known behaviour, rules, storage."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from lonlib.config import PendulumConfig, Scoring
from lonlib.task.behaviour import (
    LABELS,
    BehaviourDescriptor,
    BehaviourThresholds,
    describe,
    descriptors_of,
    label,
    relabel,
)
from lonlib.task.controllers import SwingUpBalanceController, zero_controller
from lonlib.task.policy import actor_spec, forward_numpy
from lonlib.task.rollout import evaluate


def test_the_swing_up_and_balance_controller_is_labelled_balancing():
    config = PendulumConfig(n_carts=1)
    controller = SwingUpBalanceController(config)
    d = describe(controller, config)
    assert label(d) == "balancing"
    assert d.fitness == evaluate(controller, config).fitness[0]
    assert d.upright_share[0] > 0.85 and d.upright_speed[0] < 0.2
    assert abs(d.turns[0]) == pytest.approx(0.5, abs=0.01)  # one swing up, then balance
    assert 0.85 < d.robust_min <= d.robust_mean
    assert (d.end_reason, d.end_step, d.nominal_steps) == ("STEP_LIMIT", 2000, 2000)


def test_never_pushing_from_a_hang_is_swinging_low():
    config = PendulumConfig(n_carts=2, integrator="semi-implicit")
    d = describe(zero_controller(config), config)
    assert label(d) == "swinging low"
    assert d.fitness == 0 and d.upright_share == (0.0, 0.0) and d.cart_range < 1e-3
    assert d.phase == pytest.approx(1.0)  # two identical hanging rods move as one


def test_explicit_eulers_energy_pumping_spins_an_unpushed_rod():
    # The integrator artefact of docs/model.md: from 0.1 rad of start noise, a never-pushing
    # policy's rod swings over the top after ~1400 steps and then spins.
    config = PendulumConfig(n_carts=1, initial_noise=0.1, integrator="euler", steps=3000)
    d = describe(zero_controller(config), config, Scoring(eval_seed=0))
    assert label(d) == "spinning"
    assert abs(d.turns[0]) > 20 and d.upright_share[0] > 0.2


def test_robustness_uses_perturbed_starts():
    # A rod at rest exactly upright stays up without a push; 0.01 rad of noise topples it
    # (the force motor and explicit Euler: a free cart, and the fall is not reversed).
    config = PendulumConfig(
        n_carts=1, steps=300, initial_angle=0.0, motor="force", integrator="euler"
    )
    never_push = zero_controller(config)
    exact = describe(never_push, config, Scoring(noise=0.0))
    assert exact.fitness == exact.robust_mean == exact.robust_min == 1.0
    noisy = describe(never_push, config, Scoring(noise=0.01, starts=8))
    assert noisy.fitness == 1.0 and noisy.robust_min <= noisy.robust_mean < 0.8


def descriptor(**changes):
    base = BehaviourDescriptor(
        fitness=0.3,
        fitness_all=0.3,
        fitness_mean=0.4,
        upright_share=(0.3, 0.3),
        turns=(40.0, -35.0),
        upright_speed=(6.0, 6.0),
        phase=0.9,
        cart_range=1.0,
        cart_speed=0.5,
        end_reason="STEP_LIMIT",
        end_step=2000,
        nominal_steps=2000,
        robust_mean=0.2,
        robust_min=0.1,
        robust_std=0.05,
    )
    return dataclasses.replace(base, **changes)


@pytest.mark.parametrize(
    ("changes", "expected"),
    [
        ({}, "spinning (in phase)"),
        ({"phase": -0.8}, "spinning (anti-phase)"),
        ({"phase": 0.1}, "spinning (independent)"),
        ({"turns": (3.0,), "upright_share": (0.3,), "upright_speed": (6.0,)}, "spinning"),
        (
            {"upright_share": (0.9, 0.8), "turns": (0.5, 0.5), "upright_speed": (0.1, 0.2)},
            "balancing",
        ),
        (
            {"upright_share": (0.9, 0.3), "turns": (0.5, 1.0), "upright_speed": (0.1, 4.0)},
            "one rod up",
        ),
        ({"turns": (1.0, 0.5)}, "swinging high"),
        ({"turns": (0.1, 0.1), "upright_share": (0.0, 0.0)}, "swinging low"),
        ({"end_reason": "BOUNDARY", "end_step": 400}, "stops at boundary"),
        ({"end_reason": "COLLISION", "end_step": 90}, "crash"),
        ({"end_reason": "TETHER", "end_step": 1900}, "spinning (in phase)"),  # late: not a crash
        (  # balanced, then collided: named by what it achieved
            {
                "upright_share": (0.9, 0.9),
                "turns": (0.5, 0.5),
                "upright_speed": (0.1, 0.1),
                "end_reason": "COLLISION",
                "end_step": 1700,
            },
            "balancing",
        ),
    ],
)
def test_label_rules(changes, expected):
    assert label(descriptor(**changes)) == expected
    assert expected in LABELS


def test_thresholds_are_adjustable_and_validated():
    slow_top = descriptor(upright_share=(0.6, 0.6), turns=(0.5, 0.5), upright_speed=(0.3, 0.3))
    assert label(slow_top) == "balancing"
    assert label(slow_top, BehaviourThresholds(balance_share=0.7)) == "swinging high"
    assert label(slow_top, BehaviourThresholds(balance_speed=0.2)) == "swinging high"
    with pytest.raises(ValueError, match="balance_share"):
        BehaviourThresholds(balance_share=1.5)


def test_descriptor_columns_round_trip_and_relabel_from_a_table():
    a, b = descriptor(), descriptor(phase=-0.9)
    table = pd.DataFrame([{"index": 0, **a.to_columns()}, {"index": 1, **b.to_columns()}, {}])
    got = descriptors_of(table)
    assert got[:2] == [a, b] and got[2] is None
    assert relabel(table) == ["spinning (in phase)", "spinning (anti-phase)", None]
    assert relabel(table, BehaviourThresholds(phase_lock=0.95)) == [
        "spinning (independent)",
        "spinning (independent)",
        None,
    ]


def test_robust_starts_perturb_the_nominal_start_and_bad_parameters_are_refused():
    # With the environment's own start noise, the perturbed starts sit around the nominal
    # (noisy) start: with zero extra noise they reproduce its fitness up to rounding (the
    # spinning rod is chaotic). Had they ignored it, the rod would start exactly upright and
    # at rest, and stay there: robustness 1.
    config = PendulumConfig(n_carts=1, steps=200, initial_noise=0.3, initial_angle=0.0)
    d = describe(zero_controller(config), config, Scoring(eval_seed=3, noise=0.0))
    assert d.fitness < 0.9 and d.robust_mean == pytest.approx(d.fitness, abs=0.02)
    theta = actor_spec(1).initial(np.random.default_rng(0))
    theta[3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        describe(theta, config)
    with pytest.raises(ValueError, match="shape"):
        describe(theta[:10], config)


def test_an_actor_is_described_by_its_flat_parameters():
    config = PendulumConfig(n_carts=1, steps=100)
    theta = actor_spec(1).initial(np.random.default_rng(0))
    d = describe(theta, config)
    policy_fitness = evaluate(lambda obs: forward_numpy(actor_spec(1), theta, obs), config).fitness[
        0
    ]
    assert d.fitness == policy_fitness  # one rollout: bit for bit


def labelled_trials():
    """Two runs: run 0 hops between two spinning optima of equal fitness, then to a better
    balancing one; run 1 reaches a spinning optimum of the same fitness and returns to it."""
    rows = [
        # p, run, index, parent, fitness, accepted, label
        (1e-4, 0, 0, -1, 0.25, True, "spinning"),
        (1e-4, 0, 1, 0, 0.25, True, "spinning"),
        (1e-4, 0, 2, 1, 0.10, False, "swinging high"),
        (1e-4, 0, 3, 1, 0.80, True, "balancing"),
        (1e-4, 1, 0, -1, 0.05, True, "swinging high"),
        (1e-4, 1, 1, 0, 0.25, True, "spinning"),
        (1e-4, 1, 2, 1, 0.25, True, "spinning (in phase)"),
    ]
    columns = ["p", "run", "index", "parent", "fitness", "accepted", "label"]
    return pd.DataFrame(rows, columns=columns)


def test_behavioural_lon_contracts_same_label_equal_fitness_optima():
    from lonlib.lon.behaviour import behavioural_lon
    from lonlib.lon.graphs import build_lon
    from lonlib.lon.metrics import lon_metrics

    lon = build_lon(labelled_trials(), full=True)
    assert lon.nodes["p0.0001_r0_t0"]["label"] == "spinning"
    blon = behavioural_lon(lon)
    by_label = {d["label"]: (n, d) for n, d in blon.nodes(data=True) if d["accepted"]}
    spin_name, spin = by_label["spinning"]
    # three spinning optima at 0.25, from two runs, are one node; the in-phase one is not
    assert spin["size"] == 3 and spin["fitness"] == 0.25
    assert spin["self_returns"] == 1  # r0_t0 -> r0_t1 inside the node
    assert by_label["spinning (in phase)"][1]["size"] == 1
    assert blon.has_edge(spin_name, by_label["balancing"][0])
    assert blon.has_edge(by_label["swinging high"][0], spin_name)
    assert blon.number_of_nodes() == 5  # + the rejected swinging-high optimum
    metrics = lon_metrics(blon)
    assert metrics["optima"] == 4 and metrics["sinks"] == 2


def test_behaviour_table_counts_optima_and_sinks_per_label():
    from lonlib.lon.behaviour import behaviour_table

    table = behaviour_table(labelled_trials()).set_index("label")
    assert list(table.index) == [
        "balancing",
        "spinning",
        "spinning (in phase)",
        "swinging high",
    ]
    assert table.loc["spinning", "optima"] == 3 and table.loc["spinning", "sinks"] == 0
    assert table.loc["balancing", "sinks"] == 1 and table.loc["balancing", "sink_share"] == 0.5
    assert table["sinks"].sum() == 2  # r0 ends at balancing, r1 at the in-phase spinner
    assert table.loc["swinging high", "optima"] == 1  # the rejected one is no optimum


def test_robustness_is_deterministic_with_start_noise():
    # The perturbed starts are the nominal (noisy) start plus the robustness draws, never the
    # unseeded noise a fresh simulator draws for itself.
    config = PendulumConfig(
        n_carts=1, steps=300, initial_angle=0.0, initial_noise=0.05, motor="force"
    )
    policy = zero_controller(config)
    results = {(d.robust_mean, d.robust_min) for d in (describe(policy, config) for _ in range(4))}
    assert len(results) == 1
