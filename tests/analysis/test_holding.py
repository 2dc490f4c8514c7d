"""The optima that hold their rods (lonlib.analysis.holding), on the committed one-cart LON."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lonlib.analysis import CHATTER_TOLERANT, holding_markdown, holding_summary
from lonlib.analysis.holding import (
    COLUMNS,
    NOT_COMPUTED,
    README_BEGIN,
    README_END,
    hold_measures,
    holding_table,
    splice_holding,
)
from lonlib.config import PendulumConfig, named_config
from lonlib.storage import read_experiment_trials
from lonlib.task.behaviour import relabel
from lonlib.task.rollout import Rollout, Trace

ROOT = Path(__file__).resolve().parents[2]
FOLDER = ROOT / "data" / "one-cart"
ENV = named_config("one-cart").env


@pytest.fixture(scope="module")
def whole():
    """The holding table of the committed one-cart LON (every accepted optimum's stored
    Actor replayed), and its trials."""
    trials = read_experiment_trials(FOLDER)
    return holding_table(FOLDER, trials, ENV, named_config("one-cart").ddpg.scoring), trials


@pytest.fixture(scope="module")
def small_p(whole):
    """:func:`whole` at p = 1e-4."""
    table, trials = whole
    return (
        table[table["p"] == 1e-4].reset_index(drop=True),
        trials[trials["p"] == 1e-4].reset_index(drop=True),
    )


def test_the_stored_holding_table_comes_back_from_the_stored_actors(whole):
    table, _ = whole
    stored = pd.read_csv(FOLDER / "figures" / "holding.csv")
    pd.testing.assert_frame_equal(stored, table, check_dtype=False)


def test_an_optimum_that_holds_scores_one_minus_its_swing_up(whole):
    table, trials = whole
    accepted = trials[trials["accepted"]]
    assert len(table) == len(accepted) < len(trials)  # the accepted optima, no rejected one
    keys = ["p", "run", "index"]
    pd.testing.assert_frame_equal(table[keys], accepted[keys].reset_index(drop=True))
    held = table[table["holds"]]
    assert 0 < len(held) < len(table)
    assert (held["fitness"] == 1 - held["swing_up_steps"] / ENV.steps).all()  # exactly
    assert (held["hold_angle_p90"] < ENV.upright_angle).all()
    # an optimum that turns its rod over does not hold, whatever its fitness
    assert not table.loc[table["label"] == "spinning", "holds"].any()
    assert (table.loc[~table["holds"], "fitness"] < 0.9765).all()


def test_the_best_optimum_holds_its_rod_within_a_few_hundredths_of_a_radian():
    trials = read_experiment_trials(FOLDER)
    best = trials[(trials["p"] == 1e-3) & (trials["run"] == 6) & (trials["index"] == 1)]
    (row,) = holding_table(FOLDER, best, ENV).itertuples()
    assert row.holds and row.fitness == 0.977 and row.swing_up_steps == 46
    assert row.hold_angle_p90 < 0.05 and row.upright_speed > CHATTER_TOLERANT.balance_speed / 5


def test_the_tolerant_labels_are_the_stored_descriptors_relabelled(small_p):
    table, trials = small_p
    accepted = trials[trials["accepted"]]
    assert list(table["label"]) == list(accepted["label"]) == relabel(accepted)
    assert list(table["label_chatter_tolerant"]) == relabel(accepted, CHATTER_TOLERANT)
    assert list(table["label_chatter_tolerant"]) != list(table["label"])  # the chatter
    fast = table["upright_speed"] >= CHATTER_TOLERANT.balance_speed
    assert not (table.loc[fast, "label_chatter_tolerant"] == "balancing").any()


def test_an_experiment_without_stored_actors_has_an_empty_table(tmp_path):
    trials = read_experiment_trials(FOLDER)
    table = holding_table(tmp_path, trials, ENV)
    assert table.empty and "holds" in table.columns
    assert holding_markdown(holding_summary(table)) == NOT_COMPUTED


@pytest.mark.parametrize("column", ["accepted", "label", "b_upright_speed_0", "b_end_reason"])
def test_trials_without_what_the_table_reads_are_refused_naming_it(column):
    trials = read_experiment_trials(FOLDER).drop(columns=column)
    with pytest.raises(ValueError, match=f"needs the columns.*{column}"):
        holding_table(FOLDER, trials, ENV)


def test_an_optimum_without_a_descriptor_is_refused():
    trials = read_experiment_trials(FOLDER).head(3).assign(b_end_reason=np.nan)
    with pytest.raises(ValueError, match="no stored behaviour descriptor"):
        holding_table(FOLDER, trials, ENV)


def test_with_two_rods_the_fastest_rod_is_the_upright_speed():
    reference = Path(ROOT / "data" / "reference")
    trials = read_experiment_trials(reference)
    trials = trials[trials["accepted"]].head(4)
    env = named_config("reference").env
    table = holding_table(reference, trials, env)
    speeds = trials[["b_upright_speed_0", "b_upright_speed_1"]].to_numpy()
    np.testing.assert_array_equal(table["upright_speed"], np.nanmax(speeds, axis=1))
    assert not table["holds"].any()  # two-cart optima spin


def test_the_summary_of_a_small_table():
    table = pd.DataFrame(
        {
            "p": [1e-3, 1e-3, 1e-3, 1e-3, 1e-3, 1e-4, 1e-4],
            "run": [0, 0, 1, 1, 2, 0, 0],
            "fitness": [0.97, 0.97, 0.96, 0.96, 0.5, 0.9, 0.9],
            "label": ["swinging high"] * 4 + ["spinning"] + ["balancing"] * 2,
            "holds": [True, True, True, True, False, True, True],
            "swing_up_steps": [60, 60, 80, 80, 10, 200, 200],
            "hold_angle_p90": [0.1, 0.3, 0.2, 0.2, 2.0, 0.05, 0.05],
            "upright_speed": [1.0, 2.0, 3.0, 3.0, 9.0, 0.1, 0.1],
            "label_chatter_tolerant": ["balancing", "balancing", "swinging high"] * 1
            + ["swinging high", "spinning"]
            + ["balancing"] * 2,
        }
    )
    big, small = holding_summary(table).to_dict("records")
    assert (big["p"], big["accepted"], big["holding"], big["runs_holding"]) == (1e-3, 5, 4, 2)
    assert (big["plateau_fitness"], big["at_plateau"]) == (0.97, 2)  # a tie: the higher
    assert big["fitness"] == "0.9600–0.9700 (median 0.9650)"
    assert big["hold_angle_p90"] == "0.1–0.3 (median 0.2)"
    assert big["upright_speed"] == "1.00–3.00 (median 2.50)"
    assert big["labels"] == "swinging high 4"
    assert big["labels_chatter_tolerant"] == "balancing 2, swinging high 2"
    assert (small["fitness"], small["swing_up_steps"], small["runs_holding"]) == (
        "0.9000",
        "200",
        1,
    )


def test_the_summary_counts_the_holding_optima_per_p_larger_p_first():
    table = pd.read_csv(FOLDER / "figures" / "holding.csv")
    summary = holding_summary(table)
    assert list(summary["p"]) == sorted(table["p"].unique(), reverse=True)
    for row in summary.itertuples():
        group = table[table["p"] == row.p]
        assert row.accepted == len(group) and row.holding == int(group["holds"].sum())
        top = group.loc[group["holds"], "fitness"].mode().max()
        assert row.at_plateau == int((group.loc[group["holds"], "fitness"] == top).sum())
    markdown = holding_markdown(summary)
    assert markdown.count("\n|") == len(summary) + 1  # the header's rule and a row per p
    assert r"of \|φ\| from step 400" in markdown  # pipes escaped in a cell


def test_the_block_is_pasted_only_into_a_page_with_its_markers():
    page = f"head\n{README_BEGIN}\nstale\n{README_END}\ntail\n"
    pasted = splice_holding(page, "| new |", "data/x")
    assert "| new |" in pasted and "stale" not in pasted and "`data/x`" in pasted
    assert splice_holding("no markers here\n", "| new |", "data/x") == "no markers here\n"
    assert holding_summary(pd.DataFrame(columns=list(COLUMNS))).empty


def traced(phi: np.ndarray, end_step: list[int]) -> Rollout:
    """A rollout with the rod angles ``phi [T, B]`` (one rod) or ``[T, B, n]`` (0 upright)."""
    phi = (phi if phi.ndim == 3 else phi[:, :, None]) % (2 * np.pi)
    t, b, n = phi.shape
    upright = np.abs(np.angle(np.exp(1j * phi))) < np.pi / 2
    zeros = np.zeros((t, b, n))
    trace = Trace(zeros, zeros, phi, zeros, np.zeros((t, b, 10 * n)), zeros, upright, zeros[..., 0])
    none = np.zeros(b)
    return Rollout(none, none, none, none.astype(np.int8), np.array(end_step), none, trace)


def test_a_hold_lasts_from_the_first_upright_step_to_the_end_of_a_full_episode():
    config = PendulumConfig(n_carts=1, steps=10)
    down, up = np.pi, 0.1
    phi = np.full((10, 5), down)
    phi[3:, 0] = up  # upright from step 3 to the end: holds
    phi[3:, 1], phi[6, 1] = up, 2.0  # falls past horizontal once: does not hold
    phi[3:, 2] = up  # upright to its end, but the episode ended early (at step 8)
    phi[:, 3] = -up  # upright from the start, on the other side of the vertical
    hold_from = 5
    holds, swing_up, p90 = hold_measures(traced(phi, [10, 10, 8, 10, 10]), config, hold_from)
    assert list(holds) == [True, False, False, True, False]
    assert list(swing_up) == [3, 3, 3, 0, -1]
    np.testing.assert_allclose(p90[[0, 3, 4]], [up, up, np.pi])
    assert p90[1] == pytest.approx(np.quantile([up, 2.0, up, up, up], 0.9))
    _, _, late = hold_measures(traced(phi, [10, 10, 4, 10, 10]), config, hold_from)
    assert np.isnan(late[2])  # ended before hold_from: nothing to measure
    with pytest.raises(ValueError, match="trace=True"):
        hold_measures(Rollout(*[np.zeros(1)] * 6), config)


def test_an_early_end_leaves_its_last_steps_out_of_the_hold_angle():
    config = PendulumConfig(n_carts=1, steps=10)
    phi = np.zeros((10, 1))
    phi[5:8, 0], phi[8:, 0] = 0.2, 1.4  # steps 8, 9 repeat a final state past the end
    _, _, p90 = hold_measures(traced(phi, [8]), config, hold_from=5)
    assert p90[0] == pytest.approx(0.2)


def test_with_two_rods_every_rod_must_be_up_and_the_widest_angle_counts():
    config = PendulumConfig(n_carts=2, steps=10)
    phi = np.full((10, 2, 2), np.pi)
    phi[2:, :, 0] = 0.1  # the first rod up from step 2 in both rows
    phi[4:, :, 1] = -0.3  # the second from step 4
    phi[7, 1, 1] = 2.5  # row 1's second rod falls once
    holds, swing_up, p90 = hold_measures(traced(phi, [10, 10]), config, hold_from=5)
    assert list(holds) == [True, False] and list(swing_up) == [4, 4]
    assert p90[0] == pytest.approx(0.3)  # the second rod's angle, the wider one
    assert p90[1] == pytest.approx(np.quantile([0.3, 0.3, 2.5, 0.3, 0.3], 0.9))
