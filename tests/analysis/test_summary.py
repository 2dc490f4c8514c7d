"""The experiment summary (lonlib.analysis.summary) on a synthetic folder written with
lonlib.storage.trials:
every count is the stored trials', finished runs follow Algorithm 2's tolerance, and the
README block is generated between its own markers."""

import os
from pathlib import Path
from unittest import mock

import pandas as pd
import pytest

from lonlib.analysis.summary import (
    README_BEGIN,
    README_END,
    behaviour_counts,
    experiment_summary,
    splice_summary,
    summary_markdown,
)
from lonlib.config import ExperimentConfig
from lonlib.experiment.running import status
from lonlib.search.algorithm import Trial
from lonlib.storage.atomic import write_json
from lonlib.storage.inflight import FORMAT
from lonlib.storage.status import run_status
from lonlib.storage.trials import read_experiment_trials, save_step

# (fitness, accepted, improved on its start, label) per trial; tolerance 2 ends a run after
# two rejections in a row.
RUNS = {
    1e-3: [
        [(0.0, True, False, "crash"), (0.2, True, True, "spin"), (0.1, False, True, "crash"),
         (0.15, False, True, "crash")],  # finished: two rejections
        [(0.05, True, True, "spin"), (0.5, True, True, "spin"), (0.3, False, False, "stop")],
    ],
    1e-4: [
        [(0.0, True, False, "crash"), (0.0, True, False, "crash"), (0.0, True, False, "crash")],
        [(0.1, True, True, "spin")],
        [(0.7, True, True, "spin")],  # run bests 0, 0.1, 0.7: the median is not the mean
        [(0.9, True, True, "balancing")],  # run 3: beyond the 3 runs the manifest plans
    ],
}  # fmt: skip


@pytest.fixture()
def experiment(tmp_path: Path) -> Path:
    config = ExperimentConfig(name="synthetic", perturbations=(1e-3, 1e-4), runs=3, tolerance=2)
    folder = tmp_path / "exp"
    folder.mkdir()
    write_json(folder / "manifest.json", {"experiment": "synthetic", "config": config.to_dict()})
    with mock.patch.object(os, "fsync"):
        for p, runs in RUNS.items():
            for run, chain in enumerate(runs):
                trials, incumbent = [], -1
                for index, (fitness, accepted, improved, label) in enumerate(chain):
                    trials.append(
                        Trial(index, incumbent, fitness, accepted, 1.0, 100_000 * (index + 1),
                              improved=improved, behaviour={"label": label})
                    )  # fmt: skip
                    incumbent = index if accepted else incumbent
                save_step(folder, p, run, trials, None)
    return folder


def test_the_summary_counts_what_is_stored_per_p(experiment):
    summary = experiment_summary(experiment).set_index("p")
    coarse, fine = summary.loc[1e-3], summary.loc[1e-4]
    assert (coarse["runs"], coarse["finished"], coarse["started"]) == (3, 1, 1)
    assert (fine["runs"], fine["finished"], fine["started"]) == (3, 0, 3)
    assert coarse["local_searches"] == 7 and fine["local_searches"] == 5
    assert coarse["accepted"] == 4 and fine["accepted"] == 5
    assert coarse["improved"] == 5 and fine["improved"] == 2
    assert coarse["above_zero"] == 6 and fine["above_zero"] == 2
    assert coarse["runs_above_zero"] == 2 and fine["runs_above_zero"] == 2
    assert coarse["best_fitness"] == 0.5 and coarse["median_run_best"] == pytest.approx(0.35)
    assert fine["best_fitness"] == 0.7 and fine["median_run_best"] == pytest.approx(0.1)
    assert coarse["env_steps"] == 100_000 * (1 + 2 + 3 + 4) + 100_000 * (1 + 2 + 3)
    # the labels of the accepted optima (the LON's nodes), not of every local search
    assert coarse["behaviours"] == "spin 3, crash 1"
    assert fine["behaviours"] == "crash 3, spin 2" and fine["in_flight"] == 0


def test_the_summary_counts_searches_in_flight_once_per_run(experiment):
    folder = experiment / ".inflight"
    folder.mkdir()
    checkpoints = {  # named by batch ids, as lonlib names them
        "00000000000a": ([[1e-3, 1], [1e-4, 2]], [5000, 7000]),
        "00000000000b": ([[1e-4, 2]], [6000]),
    }
    for name, (runs, steps) in checkpoints.items():
        write = "00000000000f"
        payload = {"format": FORMAT, "write_id": write, "data": f"{name}.{write}.pt", "saved": 0.0}
        payload.update(runs=runs, trials=[1] * len(runs), steps=steps)
        write_json(folder / f"{name}.json", payload)
    summary = experiment_summary(experiment).set_index("p")
    assert summary.loc[1e-3, ["in_flight", "in_flight_steps"]].tolist() == [1, 5000]
    assert summary.loc[1e-4, ["in_flight", "in_flight_steps"]].tolist() == [1, 7000]
    assert "| 1 (0.01) |" in summary_markdown(summary.reset_index())


def test_the_summary_of_unlabelled_trials_names_no_behaviour(experiment):
    trials = read_experiment_trials(experiment).drop(columns="label")
    assert list(experiment_summary(experiment, trials)["behaviours"]) == ["", ""]


def test_status_needs_no_optimum_files(experiment):
    table = status(experiment).set_index("p")  # save_step above wrote no optimum
    assert table.loc[1e-3, "best_fitness"] == 0.5 and table.loc[1e-4, "best_fitness"] == 0.7


def test_run_status_has_a_line_per_planned_run_with_its_chain(experiment, capsys):
    from lonlib.cli import main

    runs = run_status(experiment).set_index(["p", "run"])
    assert len(runs) == 6  # 2 p x 3 planned runs
    first, second, unstarted = runs.loc[(1e-3, 0)], runs.loc[(1e-3, 1)], runs.loc[(1e-3, 2)]
    assert (first["state"], first["end_reason"], first["failures"]) == ("finished", "tolerance", 2)
    assert first["fitness"] == "0.000 0.200 0.100x 0.150x" and first["best_fitness"] == 0.2
    assert (second["state"], second["failures"], second["accepted"]) == ("started", 1, 2)
    assert second["best_fitness"] == 0.5  # the incumbent, not the last trial
    assert unstarted["state"] == "not started" and unstarted["local_searches"] == 0
    assert not runs["in_flight"].any()
    main(["status", str(experiment), "--runs"])
    assert "0.050 0.500 0.300x" in capsys.readouterr().out


def test_behaviour_counts_put_the_most_frequent_first():
    labels = pd.Series(["b", "a", "c", "c", None, "b", "c"])
    assert behaviour_counts(labels) == "c 3, b 2, a 1"
    assert behaviour_counts(pd.Series([None, None])) == ""


def test_the_readme_block_is_generated_between_its_markers(experiment):
    table = summary_markdown(experiment_summary(experiment))
    row = "| 0.001 | 1 / 1 / 3 | 7 (4, 5, 6) | 2 | 0.5 | 0.35 | 1.60 | 0 (0.00) |"
    row += " spin 3, crash 1 |"
    assert "| behaviours of the accepted optima |" in table
    assert row in table
    readme = f"intro\n{README_BEGIN}\nold\n{README_END}\noutro\n"
    pasted = splice_summary(readme, table, "data/exp")
    assert "old" not in pasted and table.strip() in pasted
    assert pasted.startswith(f"intro\n{README_BEGIN}\n*Generated from `data/exp`")
    assert pasted.endswith(f"{table.strip()}\n{README_END}\noutro\n")
