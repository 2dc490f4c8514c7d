"""The claims on a LON re-scored with the robust fitness (lonlib.analysis.claims_rescored): the
structure stays the nominal sample's, each accepted node takes its own robust value, a
partial re-scoring is refused, and the side-by-side table sets the two verdicts together."""

import numpy as np
import pandas as pd
import pytest

from lonlib.analysis.claims import CONTRADICTED, REPRODUCED, claims_from_trials
from lonlib.analysis.claims_rescored import (
    FILES,
    README_BEGIN,
    README_END,
    claims_side_by_side,
    rescore_trials,
    side_by_side_markdown,
    splice_side_by_side,
    write_robust_claims,
)
from lonlib.storage.trials import read_experiment_trials
from tests.analysis.test_claims import PAPER_LIKE, WORSE, verdicts, write_experiment


@pytest.fixture(scope="module")
def trials(tmp_path_factory):
    folder = write_experiment(
        tmp_path_factory.mktemp("rescored") / "exp",
        {1e-3: WORSE, 1e-4: PAPER_LIKE},
        descriptors="scattered",
    )
    return read_experiment_trials(folder)


@pytest.fixture(scope="module")
def nominal(trials):
    return claims_from_trials(trials)


def replayed_as(trials: pd.DataFrame, robust: np.ndarray) -> pd.DataFrame:
    """A replay_optima-like frame for every trial, in reversed row order (matching must go by
    (p, run, index), not by position)."""
    frame = trials[["p", "run", "index", "accepted", "fitness"]].assign(robust_mean=robust)
    return frame.iloc[::-1].reset_index(drop=True)


def test_each_accepted_node_takes_its_own_robust_value(trials):
    robust = trials["fitness"].to_numpy() * 0.5 + trials["run"].to_numpy() * 1e-3
    out = rescore_trials(trials, replayed_as(trials, robust))
    accepted = trials["accepted"].to_numpy(bool)
    assert np.array_equal(out["fitness"].to_numpy()[accepted], robust[accepted])
    # rejected trials are no LON nodes and keep the fitness they were rejected with
    assert np.array_equal(out["fitness"][~accepted], trials["fitness"][~accepted])
    assert out.drop(columns="fitness").equals(trials.drop(columns="fitness"))
    assert not out["fitness"].equals(trials["fitness"])  # the input is not changed in place
    # by default the robust mean, not another replayed column
    other = replayed_as(trials, robust).assign(replayed=0.0, robust_min=0.0)
    assert rescore_trials(trials, other)["fitness"].equals(out["fitness"])


def test_the_same_values_give_the_same_claims(trials, nominal):
    same = claims_from_trials(rescore_trials(trials, replayed_as(trials, trials["fitness"])))
    pd.testing.assert_frame_equal(nominal, same)


def test_a_robust_fitness_that_ranks_the_runs_otherwise_changes_the_verdict(trials, nominal):
    """At p = 1e-4 the paper-like runs keep 2 % of their fitness under noise: their bests
    fall below p = 1e-3's, and claim c (1e-4 better) turns from reproduced to contradicted."""
    keep = np.where(trials["p"].to_numpy() == 1e-4, 0.02, 1.0)
    robust = trials["fitness"].to_numpy() * keep
    rescored = claims_from_trials(rescore_trials(trials, replayed_as(trials, robust)))
    assert verdicts(nominal)["c"] == REPRODUCED
    assert verdicts(rescored)["c"] == CONTRADICTED
    table = claims_side_by_side(nominal, rescored).set_index("claim")
    assert table.loc["c", "verdict (nominal)"] == REPRODUCED
    assert table.loc["c", "verdict (robust)"] == CONTRADICTED
    assert table.loc["c", "effect (robust)"].startswith("-")
    markdown = side_by_side_markdown(claims_side_by_side(nominal, rescored))
    assert "not a LON sampled with the robust one" in markdown
    assert markdown.count("\n| ") == 6  # the header and claims a to e


def test_an_accepted_trial_without_a_replayed_actor_is_refused(trials):
    replayed = replayed_as(trials, trials["fitness"])
    row = trials[trials["accepted"]].iloc[3]
    keep = ~(
        (replayed["p"] == row["p"])
        & (replayed["run"] == row["run"])
        & (replayed["index"] == row["index"])
    )
    with pytest.raises(ValueError, match=rf"run {int(row['run'])}, index {int(row['index'])}"):
        rescore_trials(trials, replayed[keep])
    rejected = trials[~trials["accepted"]].iloc[0]
    keep = ~((replayed["run"] == rejected["run"]) & (replayed["index"] == rejected["index"]))
    rescore_trials(trials, replayed[keep])  # a rejected trial is not needed
    with pytest.raises(ValueError, match="no column 'robust_min'"):
        rescore_trials(trials, replayed, "robust_min")
    nan = replayed.copy()
    nan.loc[nan["accepted"].to_numpy().nonzero()[0][2], "robust_mean"] = np.nan
    with pytest.raises(ValueError, match="no stored Actor, or NaN"):
        rescore_trials(trials, nan)
    with pytest.raises(ValueError, match=r"index \d+ is there twice"):
        rescore_trials(trials, pd.concat([replayed, replayed.iloc[[5]]]))
    nothing = replayed.iloc[:0].drop(columns="robust_mean")  # replay_optima without Actors
    with pytest.raises(ValueError, match="run 0, index 0 has no replayed robust_mean"):
        rescore_trials(trials, nothing)


def test_the_side_by_side_table_goes_by_position_not_by_index(trials, nominal):
    robust = claims_from_trials(rescore_trials(trials, replayed_as(trials, trials["fitness"] / 2)))
    want = claims_side_by_side(nominal, robust)
    shuffled = claims_side_by_side(nominal, robust.set_axis(robust.index[::-1]))
    pd.testing.assert_frame_equal(shuffled, want)
    assert list(want["n (robust)"]) == list(robust["n"])
    assert list(want["n (nominal)"]) == list(nominal["n"])
    row = robust.iloc[2]  # claim c: low < high
    assert want["effect (robust)"][2] == (
        f"{row['effect']:.4g} [{row['ci_low']:.4g}, {row['ci_high']:.4g}]"
    )
    assert want["effect (nominal)"][2].startswith(f"{nominal.iloc[2]['effect']:.4g} [")


def test_robust_claims_are_written_or_skipped_with_a_warning(trials, nominal, tmp_path):
    robust_values = trials["fitness"].to_numpy() * 0.5
    replayed = replayed_as(trials, robust_values)
    robust, side, paths = write_robust_claims(trials, replayed, nominal, tmp_path)
    assert [p.name for p in paths] == list(FILES)
    want = claims_from_trials(rescore_trials(trials, replayed))
    pd.testing.assert_frame_equal(robust, want)
    assert not robust.equals(nominal)
    pd.testing.assert_frame_equal(side, claims_side_by_side(nominal, want))
    assert (tmp_path / FILES[2]).read_text() == side_by_side_markdown(side)
    stored = pd.read_csv(tmp_path / FILES[0])
    assert list(stored["verdict"]) == list(want["verdict"])
    assert np.allclose(stored["effect"], want["effect"], equal_nan=True)
    # an accepted optimum without its Actor: a warning, and the earlier files go
    first = trials[trials["accepted"]].iloc[0]
    partial = replayed[~((replayed["run"] == first["run"]) & (replayed["index"] == first["index"]))]
    with pytest.warns(UserWarning, match="robust fitness skipped: .*no stored Actor"):
        robust, side, paths = write_robust_claims(trials, partial, nominal, tmp_path)
    assert robust.empty and side.empty and paths == []
    assert not any((tmp_path / name).exists() for name in FILES)


def test_tables_of_different_claims_are_not_set_side_by_side(nominal):
    with pytest.raises(ValueError, match="different claims"):
        claims_side_by_side(nominal, nominal.iloc[:4])


def test_the_side_by_side_table_is_pasted_between_its_markers_only(nominal):
    markdown = side_by_side_markdown(claims_side_by_side(nominal, nominal))
    page = f"a\n{README_BEGIN}\nold\n{README_END}\nb\n"
    pasted = splice_side_by_side(page, markdown, "data/x")
    assert pasted.startswith(f"a\n{README_BEGIN}\n*Generated from `data/x`")
    assert pasted.endswith(f"{markdown.strip()}\n{README_END}\nb\n") and "old" not in pasted
    assert splice_side_by_side("no markers\n", markdown, "data/x") == "no markers\n"
