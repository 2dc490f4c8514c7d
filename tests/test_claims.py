"""The paper's claims on synthetic experiment folders written with lonlib.store: every
verdict can come out each way, the tests point the right way, the table renders, and the
analysis-only command leaves the stored runs as they were."""

import hashlib
import math
import os
import subprocess
from pathlib import Path
from unittest import mock

import numpy as np
import pandas as pd
import pytest

from lonlib.basin_hopping import Trial
from lonlib.claims import (
    NOT_REPRODUCED,
    NOT_TESTABLE,
    REPRODUCED,
    claims_from_trials,
    paper_claims,
    peaks_beside_paper,
)
from lonlib.claims_report import README_BEGIN, README_END, claims_markdown, markdown_table
from lonlib.effect_size import bootstrap_delta_ci, cliffs_delta, compare_greater
from lonlib.experiment import ExperimentConfig
from lonlib.store import read_experiment_trials, save_step, write_json
from lonlib.summary import README_BEGIN as SUMMARY_BEGIN
from lonlib.summary import README_END as SUMMARY_END
from lonlib.summary import experiment_summary, summary_markdown

REPO = Path(__file__).resolve().parent.parent

# Sinks of the paper's Fig. 4 at p = 1e-4: five levels, the two lowest the strongest; the
# runs ending at 0.72 pass 0.55 and none stops in [0.6, 0.7).
PAPER_LIKE = [(0.22,)] * 10 + [(0.32,)] * 8 + [(0.46,)] * 4 + [(0.55,)] * 4 + [(0.55, 0.72)] * 4
WORSE = [(0.22,)] * 20 + [(0.32,)] * 10  # p = 1e-3: lower bests


def write_experiment(folder: Path, runs: dict[float, list[tuple[float, ...]]], labels="run"):
    """An experiment folder as lonlib.store writes it: per p, one run per chain of accepted
    fitness levels after a start at a fitness unique to the run, then two rejected trials.
    ``labels``: ``"run"`` (a behaviour label unique to each run), ``"level"`` (one label per
    fitness level, shared across runs) or None (no behaviour columns). Files are written
    atomically as in an experiment, without flushing them to disk (a test's speed)."""
    with mock.patch.object(os, "fsync"):
        return _write_experiment(folder, runs, labels)


def _write_experiment(folder: Path, runs: dict[float, list[tuple[float, ...]]], labels: str | None):
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
        tmp_path_factory.mktemp("paper") / "exp", {1e-3: WORSE, 1e-4: PAPER_LIKE}
    )


def test_a_paper_like_experiment_reproduces_every_claim(paper_like):
    table = paper_claims(paper_like)
    assert list(table["claim"]) == ["a", "b", "c", "d", "e"]
    assert set(verdicts(table).values()) == {REPRODUCED}, table[["claim", "evidence"]]
    row = table.set_index("claim")
    assert row.loc["a", "statistic"] == 5  # five typical peaks
    assert row.loc["a", "p"] == 1e-4  # Figs. 3-5 are at p = 1e-4
    assert row.loc["b", "statistic"] == 8  # weakest low peak (0.32) vs strongest other (4)
    assert row.loc["b", "effect"] == pytest.approx(2.0)
    assert row.loc["c", "p_value"] < 0.01 and row.loc["c", "ci_low"] > 0
    assert row.loc["c", "effect"] == pytest.approx(420 / 900)  # Cliff's delta by hand
    assert row.loc["d", "effect"] == 0.0
    assert row.loc["e", "statistic"] == 0 and row.loc["e", "n"] == 12
    assert row.loc["e", "p_value"] == pytest.approx((2 / 3) ** 12)
    assert "Mann-Whitney" in row.loc["c", "evidence"] and "CI [" in row.loc["c", "evidence"]


def test_a_flat_quick_sized_experiment_is_not_testable(tmp_path):
    flat = write_experiment(tmp_path / "flat", {1e-3: [(0.0,)] * 4, 1e-4: [(0.0,)] * 4}, None)
    table = paper_claims(flat).set_index("claim")
    assert set(table["verdict"]) == {NOT_TESTABLE}
    assert "fewer than 10" in table.loc["a", "evidence"]
    assert "4 runs at p = 1e-4" in table.loc["c", "evidence"]
    assert "no behaviour labels" in table.loc["d", "evidence"]


def test_claim_a_needs_several_typical_levels(tmp_path):
    # three stray sinks are detected peaks, but one sink each: no typical optimum
    one_level = [(0.40,)] * 12 + [(0.10,), (0.70,), (0.90,)]
    table = paper_claims(write_experiment(tmp_path / "x", {1e-4: one_level}))
    row = table.set_index("claim").loc["a"]
    assert row["verdict"] == NOT_REPRODUCED and row["statistic"] == 1
    assert table.set_index("claim").loc["b", "verdict"] == NOT_TESTABLE  # one typical peak
    few_levels = [(0.40,)] * 15 + [(0.60,)] * 15
    row = paper_claims(write_experiment(tmp_path / "y", {1e-4: few_levels})).iloc[0]
    assert row["verdict"] == NOT_TESTABLE and "2 distinct fitness" in row["evidence"]


def test_claim_b_fails_when_the_high_basins_are_stronger(tmp_path):
    high = [(0.22,)] * 3 + [(0.32,)] * 3 + [(0.46,)] * 4 + [(0.55,)] * 8 + [(0.72,)] * 10
    table = paper_claims(write_experiment(tmp_path / "x", {1e-4: high})).set_index("claim")
    assert table.loc["a", "verdict"] == REPRODUCED
    assert table.loc["b", "verdict"] == NOT_REPRODUCED
    assert table.loc["b", "statistic"] == 3 and table.loc["b", "effect"] == pytest.approx(0.3)
    # one low peak short of beating the others is enough to fail
    close = [(0.22,)] * 10 + [(0.32,)] * 4 + [(0.46,)] * 4 + [(0.55,)] * 4 + [(0.72,)] * 3
    table = paper_claims(write_experiment(tmp_path / "y", {1e-4: close})).set_index("claim")
    assert table.loc["b", "verdict"] == NOT_REPRODUCED


def test_claim_c_points_from_1e_4_to_1e_3(tmp_path):
    swapped = write_experiment(tmp_path / "swapped", {1e-3: PAPER_LIKE, 1e-4: WORSE})
    row = paper_claims(swapped).set_index("claim").loc["c"]
    assert row["verdict"] == NOT_REPRODUCED
    assert row["p_value"] > 0.5 and row["effect"] == pytest.approx(-420 / 900)
    assert row["ci_high"] < 0
    # significant one-sided, but the bootstrap interval of Cliff's delta reaches 0
    borderline = write_experiment(
        tmp_path / "borderline", {1e-3: [(0.32,)] * 3 + [(0.46,)] * 5, 1e-4: [(0.46,)] * 8}
    )
    row = paper_claims(borderline).set_index("claim").loc["c"]
    assert row["p_value"] < 0.05 and row["ci_low"] <= 0 < row["effect"]
    assert row["verdict"] == NOT_REPRODUCED
    one_p = paper_claims(write_experiment(tmp_path / "one", {1e-4: PAPER_LIKE}))
    row = one_p.set_index("claim").loc["c"]
    assert row["verdict"] == NOT_TESTABLE and "stored: 0.0001" in row["evidence"]
    few = write_experiment(tmp_path / "few", {1e-3: WORSE[:4], 1e-4: PAPER_LIKE})
    assert paper_claims(few).set_index("claim").loc["c", "verdict"] == NOT_TESTABLE


def test_claim_c_is_deterministic_and_its_interval_depends_on_the_seed(paper_like):
    trials = read_experiment_trials(paper_like)
    first = claims_from_trials(trials, resamples=300, seed=1).set_index("claim").loc["c"]
    again = claims_from_trials(trials, resamples=300, seed=1).set_index("claim").loc["c"]
    other = claims_from_trials(trials, resamples=300, seed=2).set_index("claim").loc["c"]
    assert (first["ci_low"], first["ci_high"]) == (again["ci_low"], again["ci_high"])
    assert (first["ci_low"], first["ci_high"]) != (other["ci_low"], other["ci_high"])
    assert first["p_value"] == other["p_value"]


def test_claim_d_counts_runs_meeting_in_the_behavioural_lon(tmp_path):
    shared = write_experiment(tmp_path / "shared", {1e-4: PAPER_LIKE}, labels="level")
    row = paper_claims(shared).set_index("claim").loc["d"]
    # 30 distinct starts and one node per level: 0.22 to 0.55 reached from several starts,
    # 0.72 only from the one 0.55 node
    assert row["verdict"] == NOT_REPRODUCED
    assert row["n"] == 35 and row["statistic"] == 4 and row["effect"] == pytest.approx(4 / 35)
    unlabelled = write_experiment(tmp_path / "none", {1e-4: PAPER_LIKE}, labels=None)
    assert paper_claims(unlabelled).set_index("claim").loc["d", "verdict"] == NOT_TESTABLE


def test_claim_e_fails_when_optima_fill_0_6_to_0_7(tmp_path):
    filled = [(0.22,)] * 10 + [(0.55, 0.65, 0.72)] * 6 + [(0.65,)] * 6
    row = paper_claims(write_experiment(tmp_path / "x", {1e-4: filled})).set_index("claim").loc["e"]
    assert row["verdict"] == NOT_REPRODUCED and row["statistic"] == 12 and row["n"] == 24
    sparse = [(0.22,)] * 25 + [(0.55,)] * 3
    row = paper_claims(write_experiment(tmp_path / "y", {1e-4: sparse})).set_index("claim").loc["e"]
    assert row["verdict"] == NOT_TESTABLE and "fewer than 10 optima in 0.5-0.8" in row["evidence"]


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
    text = claims_markdown(claims_from_trials(trials), peaks_beside_paper(trials))
    lines = text.splitlines()
    assert lines[0] == "| claim | the paper says | p | evidence | verdict |"
    assert lines[1] == "|---|---|---|---|---|"
    rows = [line for line in lines[2:7]]
    assert [r.split(" | ")[0] for r in rows] == ["| a", "| b", "| c", "| d", "| e"]
    assert all(r.endswith("| **reproduced** |") for r in rows)
    assert "| c | “the smaller perturbation (1e-4)" in text and "| 1e-4 vs 1e-3 |" in text
    assert "sink histogram (Fig. 4, 30 sinks) and the optima histogram (Fig. 5, " in text
    peaks = lines[
        lines.index(
            "| paper peak | nearest sinks peak | distance (sinks) "
            "| nearest optima peak | distance (optima) |"
        ) :
    ]
    assert [r.split(" | ")[0] for r in peaks[2:]] == [
        "| 0.22",
        "| 0.32",
        "| 0.46",
        "| 0.55",
        "| 0.72",
    ]
    assert markdown_table(pd.DataFrame({"x": ["a|b"], "y": [float("nan")]})) == (
        "| x | y |\n|---|---|\n| a\\|b |  |"
    )


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

    folder = write_experiment(tmp_path / "exp", {1e-3: WORSE[:6], 1e-4: PAPER_LIKE[::3]})
    before = hashes(folder)
    readme = tmp_path / "README.md"
    readme.write_text(
        f"intro\n{SUMMARY_BEGIN}\nold summary\n{SUMMARY_END}\n"
        f"{README_BEGIN}\nold table\n{README_END}\noutro\n"
    )
    main(["analyse", str(folder), "--readme", str(readme)])
    after = hashes(folder)
    assert {k: v for k, v in after.items() if not k.startswith("figures/")} == before
    figures = folder / "figures"
    for name in ("fig2_optima_boxplot.png", "fig4_sinks_p=0.0001.png", "peaks.csv", "claims.md"):
        assert (figures / name).stat().st_size > 0, name
    claims = pd.read_csv(figures / "claims.csv")
    assert list(claims["claim"]) == ["a", "b", "c", "d", "e"]
    trials = read_experiment_trials(folder)
    expected = claims_markdown(claims_from_trials(trials), peaks_beside_paper(trials))
    assert (figures / "claims.md").read_text() == expected
    pasted = readme.read_text()
    summary = summary_markdown(experiment_summary(folder))
    assert summary_markdown(pd.read_csv(figures / "summary.csv")) == summary
    assert pasted.startswith(f"intro\n{SUMMARY_BEGIN}\n*Generated from `{folder}`")
    assert f"{summary.strip()}\n{SUMMARY_END}\n{README_BEGIN}\n*Generated from" in pasted
    assert "old table" not in pasted and "old summary" not in pasted
    assert pasted.endswith(f"{expected.strip()}\n{README_END}\noutro\n")
    assert "written to" in capsys.readouterr().out


def test_the_analysis_only_command_refuses_a_folder_without_an_experiment(tmp_path, capsys):
    from lonlib.cli import main

    missing = tmp_path / "data" / "nothing"
    with pytest.raises(SystemExit) as exit_info:
        main(["analyse", str(missing)])
    assert exit_info.value.code == 2
    assert f"no experiment in {missing}" in capsys.readouterr().err
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
