"""The paper's claims on synthetic experiment folders written with lonlib.storage.trials: every
claim can come out reproduced, contradicted, inconclusive and not testable, the tests point the
right way, the table renders, and the analysis-only command leaves the stored runs as they
were."""

import hashlib
import math
import os
import subprocess
from pathlib import Path
from unittest import mock

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from lonlib.analysis.claims import (
    CONFIDENCE,
    CONTRADICTED,
    INCONCLUSIVE,
    NOT_TESTABLE,
    REPRODUCED,
    bootstrap_typical_peaks,
    claim_d_curve,
    claims_from_trials,
    clopper_pearson,
    paper_claims,
    peaks_beside_paper,
    typical_peaks,
)
from lonlib.analysis.claims_power import power_table
from lonlib.analysis.claims_report import README_BEGIN, README_END, claims_markdown, markdown_table
from lonlib.analysis.claims_rescored import NOT_COMPUTED
from lonlib.analysis.claims_rescored import README_BEGIN as ROBUST_BEGIN
from lonlib.analysis.claims_rescored import README_END as ROBUST_END
from lonlib.analysis.effect_size import bootstrap_delta_ci, cliffs_delta, compare_greater
from lonlib.analysis.summary import README_BEGIN as SUMMARY_BEGIN
from lonlib.analysis.summary import README_END as SUMMARY_END
from lonlib.analysis.summary import experiment_summary, summary_markdown
from lonlib.config import ExperimentConfig
from lonlib.search.algorithm import Trial
from lonlib.storage.atomic import write_json
from lonlib.storage.trials import read_experiment_trials, save_step

REPO = Path(__file__).resolve().parents[2]

# Sinks of the paper's Fig. 4 at p = 1e-4: five levels, the two lowest the strongest; the
# runs ending at 0.72 pass 0.55 and none stops in [0.6, 0.7).
PAPER_LIKE = [(0.22,)] * 20 + [(0.32,)] * 16 + [(0.46,)] * 4 + [(0.55,)] * 4 + [(0.55, 0.72)] * 4
WORSE = [(0.22,)] * 20 + [(0.32,)] * 10  # p = 1e-3: lower bests
FEATURES = ("upright_share_0", "upright_share_1", "turns_0", "turns_1", "phase", "cart_range")


def descriptor(key: int) -> dict:
    """Behaviour columns drawn from a generator seeded with ``key``: two keys give
    behaviours apart (in six standardised features), one key the same behaviour."""
    values = np.random.default_rng(key).uniform(0, 1, len(FEATURES))
    columns = {f"b_{name}": float(v) for name, v in zip(FEATURES, values, strict=True)}
    return columns | {"b_cart_speed": 1.0, "b_end_step": 2000, "b_nominal_steps": 2000}


def write_experiment(folder: Path, runs, labels="run", descriptors=None):
    """An experiment folder as lonlib.storage.trials writes it: per p, one run per chain of accepted
    fitness levels after a start at a fitness unique to the run, then two rejected trials.
    ``labels``: ``"run"`` (a behaviour label unique to each run), ``"level"`` (one label per
    fitness level, shared across runs) or None (no label). ``descriptors``: None (no
    behaviour columns), ``"scattered"`` (every optimum its own behaviour), ``"sparse"``
    (every optimum its own behaviour but the runs' starts, which share one: nodes merge,
    none is entered twice) or ``"level"`` (one behaviour per fitness level, shared across
    runs). Files are written atomically as
    in an experiment, without flushing them to disk (a test's speed)."""
    with mock.patch.object(os, "fsync"):
        return _write_experiment(folder, runs, labels, descriptors)


def _write_experiment(folder: Path, runs, labels, descriptors):
    config = ExperimentConfig(name="synthetic", perturbations=tuple(runs) or (1e-4,), runs=1)
    folder.mkdir(parents=True, exist_ok=True)
    write_json(folder / "manifest.json", {"experiment": "synthetic", "config": config.to_dict()})
    for p, chains in runs.items():
        for run, chain in enumerate(chains):
            levels = [0.001 * (run + 1), *chain, 0.0, 0.0]
            trials, best, incumbent = [], -math.inf, -1
            for index, fitness in enumerate(levels):
                accepted = fitness >= best
                label = {"run": f"run {run}", "level": f"level {fitness:.2f}", None: None}[labels]
                behaviour = {} if label is None else {"label": label}
                key = {
                    "scattered": 1000 * run + index,
                    "level": round(fitness * 1e4),
                    "sparse": 999_999 if index == 0 else 1000 * run + index,
                }
                if descriptors:
                    behaviour |= descriptor(key[descriptors])
                trials.append(
                    Trial(index, incumbent, fitness, accepted, 0.0, 0, behaviour=behaviour)
                )
                if accepted:
                    best, incumbent = fitness, index
            save_step(folder, p, run, trials, None)
    return folder


def verdicts(table: pd.DataFrame) -> dict[str, str]:
    return dict(zip(table["claim"], table["verdict"], strict=True))


@pytest.fixture(scope="module")
def paper_like(tmp_path_factory):
    return write_experiment(
        tmp_path_factory.mktemp("paper") / "exp",
        {1e-3: WORSE, 1e-4: PAPER_LIKE},
        descriptors="sparse",
    )


def test_a_paper_like_experiment_reproduces_every_claim(paper_like):
    table = paper_claims(paper_like)
    assert list(table["claim"]) == ["a", "b", "c", "d", "e"]
    assert set(verdicts(table).values()) == {REPRODUCED}, table[["claim", "evidence"]]
    row = table.set_index("claim")
    assert row.loc["a", "statistic"] == 5 and row.loc["a", "ci_low"] >= 3  # five typical peaks
    assert row.loc["a", "p"] == 1e-4  # Figs. 3-5 are at p = 1e-4
    assert row.loc["b", "statistic"] == 16  # weakest low peak (0.32) vs strongest other (4)
    assert row.loc["b", "effect"] == 4.0
    low, _ = clopper_pearson(16, 20, CONFIDENCE)
    assert row.loc["b", "ci_low"] == pytest.approx(low / (1 - low)) and low > 0.5
    assert row.loc["c", "p_value"] < 0.01 and row.loc["c", "ci_low"] > 0
    assert row.loc["c", "effect"] == pytest.approx(480 / 1440)  # Cliff's delta by hand
    assert row.loc["d", "effect"] == 0.0 and row.loc["d", "n"] == 53  # the starts' node + 52
    assert row.loc["e", "statistic"] == 0 and row.loc["e", "n"] == 12
    assert row.loc["e", "p_value"] == pytest.approx((2 / 3) ** 12)
    assert row.loc["e", "ci_high"] < 1 and row.loc["e", "threshold"] == 1
    assert "Mann-Whitney" in row.loc["c", "evidence"] and "CI [" in row.loc["c", "evidence"]
    assert list(row["direction"]) == [">= 3", "> 1", "> 0", "<= 0.05", "< 1"]


def test_claim_d_is_not_reproduced_by_a_test_that_cannot_fail(tmp_path):
    """With every optimum a node of its own, no node can have two in-edges: the share is 0
    whatever the landscape, so the verdict is inconclusive, not reproduced."""
    alone = write_experiment(tmp_path / "alone", {1e-4: PAPER_LIKE}, None, "scattered")
    row = paper_claims(alone).set_index("claim").loc["d"]
    assert (row["n"], row["statistic"], row["effect"]) == (100, 0, 0.0)
    assert row["verdict"] == INCONCLUSIVE and "the test cannot fail" in row["evidence"]
    merged = write_experiment(tmp_path / "merged", {1e-4: PAPER_LIKE}, None, "sparse")
    row = paper_claims(merged).set_index("claim").loc["d"]
    assert row["verdict"] == REPRODUCED and "cannot fail" not in row["evidence"]


def test_a_flat_quick_sized_experiment_is_not_testable(tmp_path):
    flat = write_experiment(tmp_path / "flat", {1e-3: [(0.0,)] * 3, 1e-4: [(0.0,)] * 3}, None)
    table = paper_claims(flat).set_index("claim")
    assert set(table["verdict"]) == {NOT_TESTABLE}
    assert "fewer than 10" in table.loc["a", "evidence"]
    assert "3 runs at p = 1e-4" in table.loc["c", "evidence"]
    assert "no behaviour descriptors" in table.loc["d", "evidence"]


# Per case: runs per p, the descriptors, and the verdict each claim must reach (claims not
# named are not checked). Every claim reaches each of the four verdicts in some case.
FIVE_EVEN = [(0.22,)] * 8 + [(0.32,)] * 8 + [(0.46,)] * 6 + [(0.55,)] * 6 + [(0.72,)] * 6
LEVEL_MEETINGS = [(round(0.30 + 0.05 * (run % 10), 2),) for run in range(20)]
VERDICT_CASES = {
    "two sink levels, the high one strong": (
        {1e-4: [(0.40,)] * 15 + [(0.60,)] * 15},
        None,
        {"a": CONTRADICTED},
    ),
    "a weak third level": (
        {1e-4: [(0.22,)] * 10 + [(0.46,)] * 10 + [(0.72,)] * 2},
        None,
        {"a": INCONCLUSIVE},
    ),
    "nine sinks": (
        {1e-4: [(0.22,)] * 5 + [(0.46,)] * 4},
        None,
        {"a": NOT_TESTABLE, "b": NOT_TESTABLE},
    ),
    "the low basin weak": (
        {1e-4: [(0.22,)] * 3 + [(0.72,)] * 20},
        None,
        {"a": CONTRADICTED, "b": CONTRADICTED},
    ),
    "the low basin half as strong": (  # 10 of 30: the 90 % upper end is 0.4994
        {1e-4: [(0.22,)] * 10 + [(0.72,)] * 20},
        None,
        {"b": CONTRADICTED},
    ),
    "five even basins": ({1e-4: FIVE_EVEN}, None, {"a": REPRODUCED, "b": INCONCLUSIVE}),
    "one typical level and strays": (
        {1e-4: [(0.40,)] * 12 + [(0.10,), (0.70,), (0.90,)]},
        None,
        {"b": NOT_TESTABLE},
    ),
    "1e-3 better": ({1e-3: PAPER_LIKE, 1e-4: WORSE}, None, {"c": CONTRADICTED}),
    "no difference between p": ({1e-3: WORSE, 1e-4: WORSE}, None, {"c": INCONCLUSIVE}),
    "one p": ({1e-4: PAPER_LIKE}, None, {"c": NOT_TESTABLE}),
    "three runs at 1e-3": ({1e-3: WORSE[:3], 1e-4: PAPER_LIKE}, None, {"c": NOT_TESTABLE}),
    "runs meet at shared behaviours": ({1e-4: LEVEL_MEETINGS}, "level", {"d": CONTRADICTED}),
    "a few runs meet": ({1e-4: PAPER_LIKE}, "level", {"d": INCONCLUSIVE}),
    "no meeting, few nodes": ({1e-4: [(0.22,), (0.46,)]}, "scattered", {"d": INCONCLUSIVE}),
    "no descriptors": ({1e-4: PAPER_LIKE}, None, {"d": NOT_TESTABLE}),
    "optima fill 0.6-0.7": (
        {1e-4: [(0.55, 0.65, 0.72)] * 6 + [(0.65,)] * 12},
        None,
        {"e": CONTRADICTED},
    ),
    "a shallow dip": (  # 7 of 30: the 90 % upper end is 0.39
        {1e-4: [(0.55,)] * 12 + [(0.65,)] * 7 + [(0.75,)] * 11},
        None,
        {"e": INCONCLUSIVE},
    ),
    "few optima in 0.5-0.8": ({1e-4: [(0.22,)] * 25 + [(0.55,)] * 3}, None, {"e": NOT_TESTABLE}),
}


def test_every_claim_reaches_every_verdict_in_some_case():
    reached = {pair for *_, want in VERDICT_CASES.values() for pair in want.items()}
    for claim in "abcde":
        for verdict in (CONTRADICTED, INCONCLUSIVE, NOT_TESTABLE):
            assert (claim, verdict) in reached, (claim, verdict)


@pytest.mark.parametrize("case", list(VERDICT_CASES))
def test_each_verdict_comes_out_where_the_data_say_so(tmp_path, case):
    runs, descriptors, want = VERDICT_CASES[case]
    table = paper_claims(write_experiment(tmp_path / "x", runs, None, descriptors))
    got = verdicts(table)
    assert {claim: got[claim] for claim in want} == want, table[["claim", "evidence"]]
    rows = table.set_index("claim")
    for claim, verdict in want.items():
        row = rows.loc[claim]
        if verdict in (REPRODUCED, CONTRADICTED, INCONCLUSIVE):
            assert row["ci_low"] <= row["ci_high"] and not math.isnan(row["n"])
        else:
            assert math.isnan(row["ci_low"]) and math.isnan(row["effect"])


def test_the_verdicts_follow_the_interval_and_the_threshold(tmp_path):
    two_levels = VERDICT_CASES["two sink levels, the high one strong"][0]
    table = paper_claims(write_experiment(tmp_path / "x", two_levels))
    a = table.set_index("claim").loc["a"]
    assert (a["statistic"], a["ci_low"], a["ci_high"]) == (2, 2, 2)  # 2 levels can't make 3
    low = paper_claims(write_experiment(tmp_path / "y", {1e-4: [(0.22,)] * 3 + [(0.72,)] * 20}))
    b = low.set_index("claim").loc["b"]
    assert b["statistic"] == 3 and b["effect"] == pytest.approx(3 / 20)
    high = clopper_pearson(3, 23, CONFIDENCE)[1]
    assert b["ci_high"] == pytest.approx(high / (1 - high)) and b["ci_high"] < 1
    weak = paper_claims(write_experiment(tmp_path / "z", VERDICT_CASES["a weak third level"][0]))
    a = weak.set_index("claim").loc["a"]
    assert (a["statistic"], a["ci_low"], a["ci_high"]) == (3, 2, 3)


def test_claim_b_adjusts_only_the_end_that_one_pair_can_decide(tmp_path):
    # five even basins: 6 low x other pairs; the weakest low (8) against the strongest other
    # (6); the upper end is Bonferroni-adjusted for the 6 pairs, the lower end is not
    row = paper_claims(write_experiment(tmp_path / "x", {1e-4: FIVE_EVEN})).set_index("claim")
    b = row.loc["b"]
    low = clopper_pearson(8, 14, CONFIDENCE)[0]
    high = clopper_pearson(8, 14, 1 - 2 * 0.05 / 6)[1]
    assert b["ci_low"] == pytest.approx(low / (1 - low))
    assert b["ci_high"] == pytest.approx(high / (1 - high))
    assert b["p_value"] == pytest.approx(stats.binomtest(8, 14, 0.5, "greater").pvalue)


def test_claim_c_points_from_1e_4_to_1e_3(tmp_path):
    swapped = write_experiment(tmp_path / "swapped", {1e-3: PAPER_LIKE, 1e-4: WORSE})
    row = paper_claims(swapped).set_index("claim").loc["c"]
    assert row["verdict"] == CONTRADICTED
    assert row["p_value"] > 0.5 and row["effect"] == pytest.approx(-480 / 1440)
    assert row["ci_high"] < 0
    # two runs of eight worse at 1e-3: p = 0.085 and the interval reaches 0: inconclusive
    small = write_experiment(
        tmp_path / "small", {1e-3: [(0.32,)] * 2 + [(0.46,)] * 6, 1e-4: [(0.46,)] * 8}
    )
    row = paper_claims(small).set_index("claim").loc["c"]
    assert row["p_value"] > 0.05 and row["ci_low"] <= 0 < row["effect"] == 0.25
    assert row["verdict"] == INCONCLUSIVE
    four = write_experiment(tmp_path / "four", {1e-3: WORSE[:4], 1e-4: PAPER_LIKE[-4:]})
    assert paper_claims(four).set_index("claim").loc["c", "verdict"] == REPRODUCED


def test_claim_c_is_deterministic_and_its_interval_depends_on_the_seed(paper_like):
    trials = read_experiment_trials(paper_like)
    first = claims_from_trials(trials, resamples=300, seed=1).set_index("claim")
    again = claims_from_trials(trials, resamples=300, seed=1).set_index("claim")
    other = claims_from_trials(trials, resamples=300, seed=2).set_index("claim").loc["c"]
    pd.testing.assert_frame_equal(first, again)
    first = first.loc["c"]
    assert (first["ci_low"], first["ci_high"]) != (other["ci_low"], other["ci_high"])
    assert first["p_value"] == other["p_value"]


def test_the_bootstrap_counts_typical_peaks_as_typical_peaks_does():
    rng = np.random.default_rng(3)
    levels = rng.choice([0.0, 0.22, 0.3, 0.46, 0.55, 0.72, 0.9], 40)
    sinks = np.round(levels + rng.normal(0, 0.01, 40), 3).clip(0, 1)
    counts = bootstrap_typical_peaks(sinks, 50, 100, seed=5)
    distinct, weight = np.unique(sinks, return_counts=True)
    draws = np.random.default_rng(5).multinomial(40, weight / 40, 100)
    by_hand = [typical_peaks(np.repeat(distinct, draw), 50)["typical"].sum() for draw in draws]
    assert list(counts) == by_hand and len(set(by_hand)) > 1


def test_clopper_pearson_inverts_the_exact_binomial_test():
    for k, n in ((0, 12), (3, 12), (12, 12), (8, 14)):
        low, high = clopper_pearson(k, n, 0.9)
        assert 0 <= low <= k / n <= high <= 1
        if k < n:  # the upper end: where the one-sided test of "share < high" gives 0.05
            assert stats.binom.cdf(k, n, high) == pytest.approx(0.05)
        if k > 0:
            assert stats.binom.sf(k - 1, n, low) == pytest.approx(0.05)
    assert clopper_pearson(0, 12, 0.9)[0] == 0 and clopper_pearson(12, 12, 0.9)[1] == 1


def test_claim_d_counts_runs_meeting_in_behaviour_space(tmp_path):
    meet = write_experiment(tmp_path / "meet", {1e-4: LEVEL_MEETINGS}, "level", "level")
    row = paper_claims(meet).set_index("claim").loc["d"]
    # 20 scattered starts, 10 shared levels each reached from two starts
    assert (row["n"], row["statistic"]) == (30, 10) and row["effect"] == pytest.approx(1 / 3)
    assert row["ci_low"] > 0.05 and row["p_value"] < 0.05
    assert "label level (same label and equal fitness merged): 10 of 30 nodes" in row["evidence"]
    few = write_experiment(tmp_path / "few", {1e-4: [(0.22,), (0.46,)]}, None, "scattered")
    row = paper_claims(few).set_index("claim").loc["d"]
    assert (row["n"], row["statistic"], row["verdict"]) == (4, 0, INCONCLUSIVE)
    curve = claim_d_curve(read_experiment_trials(meet))
    assert list(curve["epsilon"]) == [round(0.1 * k, 1) for k in range(1, 21)]
    assert curve.loc[curve["epsilon"] == 0.5, "share"].item() == pytest.approx(1 / 3)
    assert (curve["ci_low"] <= curve["share"]).all() and (curve["share"] <= curve["ci_high"]).all()
    assert claim_d_curve(read_experiment_trials(few)).shape[0] == 20


def test_cliffs_delta_and_the_one_sided_test():
    assert cliffs_delta([1, 2, 3], [1, 2, 3]) == 0.0
    assert cliffs_delta([2, 3], [1, 1]) == 1.0
    assert cliffs_delta([1, 3], [2, 2, 2]) == 0.0
    assert cliffs_delta([1, 2, 3], [0, 2]) == pytest.approx((4 - 1) / 6)
    high, low = np.arange(10.0) + 5, np.arange(10.0)
    up, down = compare_greater(high, low, resamples=200), compare_greater(low, high, resamples=200)
    assert up.p_value < 0.01 < 0.99 < down.p_value
    assert up.delta == -down.delta == pytest.approx(0.75)  # 85 wins, 5 ties, 10 losses
    assert up.median_difference == 5.0
    assert bootstrap_delta_ci(high, low, 200, 0.95, 0) == bootstrap_delta_ci(
        high, low, 200, 0.95, 0
    )
    # a percentile interval stays within delta's range [-1, 1] even when skewed at its edge
    nine = compare_greater(np.r_[np.ones(9), 0.0], np.zeros(10), resamples=300)
    assert nine.delta == 0.9 and nine.ci_low <= 0.9 <= nine.ci_high <= 1.0


def test_markdown_rendering(paper_like):
    trials = read_experiment_trials(paper_like)
    claims = claims_from_trials(trials)
    text = claims_markdown(claims, peaks_beside_paper(trials), power_table(), claim_d_curve(trials))
    lines = text.splitlines()
    assert lines[0] == (
        "| claim | the paper says | p | n | statistic | effect [90 % interval] | evidence "
        "| verdict |"
    )
    assert lines[1] == "|---|---|---|---|---|---|---|---|"
    rows = [line for line in lines[2:7]]
    assert [r.split(" | ")[0] for r in rows] == ["| a", "| b", "| c", "| d", "| e"]
    assert all(r.endswith("| **reproduced** |") for r in rows)
    assert "| c | “the smaller perturbation (1e-4)" in text and "| 1e-4 vs 1e-3 | 30 |" in text
    assert "| Mann-Whitney U = " in text and "Cliff's delta: 0.3333 [" in text
    assert "; paper: > 0 |" in text and "typical peaks: 5 [" in text
    assert "sink histogram (Fig. 4, 48 sinks) and the optima histogram (Fig. 5, " in text
    peaks = lines[
        lines.index(
            "| paper peak | nearest sinks peak | distance (sinks) "
            "| nearest optima peak | distance (optima) |"
        ) :
    ]
    assert [r.split(" | ")[0] for r in peaks[2:7]] == [
        "| 0.22",
        "| 0.32",
        "| 0.46",
        "| 0.55",
        "| 0.72",
    ]
    assert "| p | ε = 0.1 | ε = 0.3 | ε = 0.5 | ε = 0.7 | ε = 1 | ε = 1.5 | ε = 2 |" in lines
    assert "| claim | smallest effect of interest | power from | needed for 80 % power" in text
    assert "| c | Cliff's delta 0.47 (large, Romano et al. 2006) | formula (Noether 1987) |" in text
    assert markdown_table(pd.DataFrame({"x": ["a|b"], "y": [float("nan")]})) == (
        "| x | y |\n|---|---|\n| a\\|b |  |"
    )
    plain = claims_markdown(claims)
    assert "ε = 0.5" not in plain and "smallest effect" not in plain


def hashes(folder: Path) -> dict[str, str]:
    return {
        str(path.relative_to(folder)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(folder.rglob("*"))
        if path.is_file()
    }


def test_the_analysis_only_command_writes_figures_and_claims_and_changes_no_stored_file(
    tmp_path, capsys
):
    from lonlib.cli import main

    folder = write_experiment(
        tmp_path / "exp", {1e-3: WORSE[:6], 1e-4: PAPER_LIKE[::3]}, descriptors="level"
    )
    before = hashes(folder)
    readme = tmp_path / "README.md"
    readme.write_text(
        f"intro\n{SUMMARY_BEGIN}\nold summary\n{SUMMARY_END}\n"
        f"{README_BEGIN}\nold table\n{README_END}\noutro\n"
        f"{ROBUST_BEGIN}\nold robust\n{ROBUST_END}\n"
    )
    with pytest.warns(UserWarning, match="robust fitness skipped.*no stored Actor"):
        main(["analyse", str(folder), "--readme", str(readme)])
    after = hashes(folder)
    assert {k: v for k, v in after.items() if not k.startswith("figures/")} == before
    figures = folder / "figures"
    for name in (
        "fig2_optima_boxplot.png",
        "fig4_sinks_p=0.0001.png",
        "peaks.csv",
        "claims.md",
        "claim_d_curve.png",
    ):
        assert (figures / name).stat().st_size > 0, name
    claims = pd.read_csv(figures / "claims.csv")
    assert list(claims["claim"]) == ["a", "b", "c", "d", "e"]
    trials = read_experiment_trials(folder)
    curve, power = claim_d_curve(trials), power_table()
    pd.testing.assert_frame_equal(pd.read_csv(figures / "claim_d_curve.csv"), curve)
    pd.testing.assert_frame_equal(pd.read_csv(figures / "power.csv"), power)
    expected = claims_markdown(claims_from_trials(trials), peaks_beside_paper(trials), power, curve)
    assert (figures / "claims.md").read_text() == expected
    pasted = readme.read_text()
    summary = summary_markdown(experiment_summary(folder))
    assert summary_markdown(pd.read_csv(figures / "summary.csv")) == summary
    assert pasted.startswith(f"intro\n{SUMMARY_BEGIN}\n*Generated from `{folder}`")
    assert f"{summary.strip()}\n{SUMMARY_END}\n{README_BEGIN}\n*Generated from" in pasted
    assert "old table" not in pasted and "old summary" not in pasted
    assert f"{expected.strip()}\n{README_END}\noutro\n" in pasted
    # no stored Actors here, so the robust re-scoring is not computed, and says so
    assert pasted.endswith(f"{NOT_COMPUTED.strip()}\n{ROBUST_END}\n")
    assert "written to" in capsys.readouterr().out


def test_the_analysis_only_command_refuses_a_folder_without_an_experiment(tmp_path, capsys):
    from lonlib.cli import main

    missing = tmp_path / "data" / "nothing"
    with pytest.raises(SystemExit) as exit_info:
        main(["analyse", str(missing)])
    assert exit_info.value.code == 2
    assert f"{missing}: no such folder" in capsys.readouterr().err
    assert not missing.exists()
    empty = write_experiment(tmp_path / "empty", {})
    with pytest.raises(SystemExit):
        main(["analyse", str(empty)])
    assert f"{empty} holds no finished local search" in capsys.readouterr().err
    assert not (empty / "figures").exists()
    no_markers = tmp_path / "README.md"
    no_markers.write_text("no markers here\n")
    with pytest.raises(SystemExit):
        main(
            [
                "analyse",
                str(write_experiment(tmp_path / "x", {1e-4: [(0.5,)]})),
                "--readme",
                str(no_markers),
            ]
        )
    assert "must hold" in capsys.readouterr().err
    claims_only = tmp_path / "CLAIMS.md"
    claims_only.write_text(f"{README_BEGIN}\n{README_END}\n")
    with pytest.raises(SystemExit):
        main(["analyse", str(tmp_path / "x"), "--readme", str(claims_only)])
    assert SUMMARY_BEGIN in capsys.readouterr().err
    assert not (tmp_path / "x" / "figures").exists()  # refused before any work


def test_make_figures_runs_the_analysis_only_command():
    dry = subprocess.run(
        ["make", "-n", "figures", "EXPERIMENT=data/some-experiment"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert dry.returncode == 0, dry.stderr
    assert "lonlib analyse data/some-experiment" in dry.stdout
    assert "sample_lon" not in dry.stdout and "lonlib run" not in dry.stdout
