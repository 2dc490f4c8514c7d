"""``lonlib verify``: a real (tiny) experiment replays exactly; damage is found and named."""

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lonlib.analysis.verify import verify_experiment
from lonlib.cli import main as cli_main
from lonlib.storage.layout import optimum_path, trials_path
from tests.conftest import reseal


def test_a_fresh_experiment_replays_every_stored_number(tiny_experiment, capsys):
    _, out, trials = tiny_experiment
    report = verify_experiment(out)
    assert report.ok and report.findings == []
    assert report.trials == report.replayed == report.starts == len(trials)
    cli_main(["verify", str(out)])
    assert "verify: OK" in capsys.readouterr().out


REFERENCE = Path(__file__).resolve().parents[2] / "data" / "reference"
REFERENCE_RUN = "p=0.0001/run_0007"
"""A run of the committed reference (8 searches, the recording of its best *stops at
boundary* optimum): small enough to replay in a test."""


def test_a_run_of_the_committed_reference_replays_every_stored_number(tmp_path):
    """Real stored data through the public path: every fitness (both aggregations), robust
    estimate, descriptor and label of the run, every rebuilt start and the recording come
    back exactly from the stored Actors, under the current result-path version."""
    copy = tmp_path / "reference"
    shutil.copytree(REFERENCE / REFERENCE_RUN, copy / REFERENCE_RUN)
    (copy / REFERENCE_RUN / "digests.json").unlink()  # a partial copy: unsealed
    shutil.copy(REFERENCE / "manifest.json", copy / "manifest.json")
    (copy / "recordings").mkdir()
    for recording in (REFERENCE / "recordings").glob("*_p=0.0001_run=7_*.rrd"):
        shutil.copy(recording, copy / "recordings" / recording.name)
    report = verify_experiment(copy)
    errors = [finding for finding in report.findings if finding.severity == "error"]
    assert report.current_version and errors == [], errors
    assert report.trials == report.replayed == report.starts == 8
    assert report.recordings == 1


@pytest.fixture
def damaged(tiny_experiment, tmp_path):
    _, out, trials = tiny_experiment
    copy = tmp_path / "damaged"
    shutil.copytree(out, copy)
    return copy, trials


def rewrite(folder, p, run, change):
    path = trials_path(folder, p, run)
    table = pd.read_parquet(path)
    change(table)
    table.to_parquet(path)


def test_a_changed_fitness_a_changed_descriptor_and_a_lost_actor_are_errors(damaged, capsys):
    folder, trials = damaged
    first = trials.iloc[0]
    p, run = float(first.p), int(first.run)

    def damage(table):
        table.loc[0, "fitness"] += 0.025
        table.loc[1, "b_turns_0"] += 1.0
        table.loc[1, "label"] = "balancing"

    rewrite(folder, p, run, damage)
    accepted = trials[(trials.p == p) & (trials.run == run) & trials.accepted].iloc[-1]
    optimum_path(folder, p, run, int(accepted["index"])).unlink()
    report = verify_experiment(folder)
    found = {(f.check, f.index) for f in report.errors}
    assert ("fitness", 0) in found and ("consistency", 0) in found
    assert ("descriptor", 1) in found and ("label", 1) in found
    assert ("actor", int(accepted["index"])) in found
    assert not report.ok
    with pytest.raises(SystemExit) as stop:
        cli_main(["verify", str(folder)])
    assert stop.value.code == 1
    assert "[fitness]" in capsys.readouterr().out


def shift_fitness_and_stamp(folder, trials, version, sessions=slice(None)):
    """Every fitness of the first run +0.5, and ``sessions`` stamped with ``version``."""
    first = trials.iloc[0]

    def damage(table):
        table["fitness"] += 0.5

    rewrite(folder, float(first.p), int(first.run), damage)
    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    for session in data["sessions"][sessions]:
        session["result_path_version"] = version
    manifest.write_text(json.dumps(data))
    reseal(folder)  # a folder written so, not a changed one: the replay checks are tested


def test_data_of_another_result_path_version_gives_warnings_not_errors(damaged):
    folder, trials = damaged
    shift_fitness_and_stamp(folder, trials, "1")  # a known, older version
    report = verify_experiment(folder)
    assert report.ok and not report.current_version
    assert {f.check for f in report.warnings} >= {"version", "fitness"}


@pytest.mark.parametrize("version", ["99", "0-older", "3"])
def test_an_unknown_result_path_version_never_turns_an_error_into_a_warning(
    damaged, version, capsys
):
    folder, trials = damaged
    shift_fitness_and_stamp(folder, trials, version, slice(-1, None))  # the last session
    report = verify_experiment(folder)
    assert not report.ok
    assert {f.check for f in report.errors} >= {"version", "fitness"}
    with pytest.raises(SystemExit):
        cli_main(["verify", str(folder)])
    out = capsys.readouterr().out
    assert "does not know" in out and "verify: FAILED" in out


def test_an_experiment_of_another_result_path_is_not_extended(damaged):
    import dataclasses

    from lonlib.experiment.running import run_experiment
    from lonlib.storage.layout import read_manifest

    folder, _ = damaged
    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    data["sessions"][0]["result_path_version"] = None
    manifest.write_text(json.dumps(data))
    reseal(folder)  # a folder written so (the root seals the sessions' versions)
    data = json.loads(manifest.read_text())
    from lonlib.config import ExperimentConfig

    config = ExperimentConfig.from_mapping(read_manifest(folder)["config"])
    run_experiment(config, folder, progress=False)  # finished: nothing to sample, no refusal
    with pytest.raises(ValueError, match="result-path version"):
        run_experiment(dataclasses.replace(config, runs=config.runs + 1), folder, progress=False)
    assert json.loads(manifest.read_text()) == data  # the refusal wrote nothing


def test_sessions_of_other_environments_or_kernels_are_warned_about(damaged):
    folder, _ = damaged
    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    first = data["sessions"][0]
    data["sessions"].append(
        {
            **first,
            "versions": data["versions"],  # a later session records its own
            "cpu": {**first["cpu"], "torch": "AVX512"},
            "environment": {"installed_sha256": "x"},
        }
    )
    manifest.write_text(json.dumps(data))
    reseal(folder)  # a folder written so (the root seals the sessions' versions)
    report = verify_experiment(folder, recordings=False)
    assert report.ok
    messages = [f.message for f in report.warnings if f.check == "provenance"]
    assert len(messages) == 2 and any("torch CPU kernels" in m for m in messages)
    (environment,) = [m for m in messages if "environment" in m]
    assert "same versions in all" in environment  # numpy, torch and python agree

    data["sessions"][-1] = {**first, "versions": {**data["versions"], "numpy": "0.0"}}
    data["sessions"][-1]["environment"] = {"installed_sha256": "x"}
    manifest.write_text(json.dumps(data))
    reseal(folder)
    (environment,) = [
        f.message
        for f in verify_experiment(folder, recordings=False).warnings
        if f.check == "provenance"
    ]
    assert "may differ" in environment and "same versions" not in environment


@pytest.fixture(scope="module")
def robust_experiment(tmp_path_factory):
    """The tiny experiment under fitness_estimate robust, with start noise and other seeds."""
    from lonlib.config import load_config
    from lonlib.experiment.running import run_experiment
    from tests.conftest import write_tiny_yaml

    folder = tmp_path_factory.mktemp("robust")
    path = write_tiny_yaml(folder)
    path.write_text(
        path.read_text()
        .replace("motor_gain: 2.0}", "motor_gain: 2.0, initial_noise: 0.05}")
        .replace(
            "patience_steps: 1000}",
            "patience_steps: 1000, fitness_estimate: robust,\n"
            "       robust_starts: 3, robust_seed: 5, eval_seed: 3}",
        )
    )
    config = load_config(path)
    assert config.ddpg.fitness_estimate == "robust" and config.env.initial_noise == 0.05
    config = dataclasses.replace(config, runs=1)
    trials = run_experiment(config, folder / "out", progress=False)
    return config, folder / "out", trials


def test_a_robust_experiment_replays_and_its_reanalysis_is_consistent(robust_experiment):
    from lonlib.analysis.conditioning import (
        edges_no_longer_improving,
        replay_optima,
        retention_curve,
        stored_actors,
    )

    config, out, trials = robust_experiment
    report = verify_experiment(out)
    assert report.ok and report.findings == [] and report.replayed == len(trials)
    assert (trials["fitness"] == trials["b_robust_mean"]).all()
    replayed = replay_optima(out, trials, config.env, config.ddpg.scoring)
    assert (replayed["replayed_estimate"] == replayed["fitness"]).all()
    assert edges_no_longer_improving(trials, replayed).empty
    _, thetas = stored_actors(out, trials)
    curve = retention_curve(
        thetas, replayed["replayed"].to_numpy(), config.env, (0.0,), config.ddpg.scoring
    )
    assert curve["median_ratio"].iloc[0] in (1.0,) or np.isnan(curve["median_ratio"].iloc[0])


def test_a_robust_fitness_changed_by_a_rounding_is_an_error(robust_experiment, tmp_path):
    _, out, trials = robust_experiment
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    first = trials.iloc[0]

    def damage(table):
        table.loc[0, "fitness"] = np.nextafter(table.loc[0, "fitness"], 2.0)

    rewrite(copy, float(first.p), int(first.run), damage)
    assert ("fitness", 0) in {(f.check, f.index) for f in verify_experiment(copy).errors}


def test_a_recording_of_another_episode_is_an_error(damaged):
    from lonlib.analysis.recordings import record
    from lonlib.storage.layout import read_manifest
    from lonlib.storage.trials import read_optimum

    folder, trials = damaged
    from lonlib.config import ExperimentConfig

    config = ExperimentConfig.from_mapping(read_manifest(folder)["config"])
    rows = trials[(trials.p == trials.p.iloc[0]) & (trials.run == trials.run.iloc[0])]
    a, b = rows.iloc[0], rows.iloc[1]
    recordings = folder / "recordings"

    def recorded(row, as_row, name):
        theta = read_optimum(optimum_path(folder, row.p, int(row.run), int(row["index"]))).theta
        keys = {"p": float(as_row.p), "run": int(as_row.run), "index": int(as_row["index"])}
        record(theta, config.env, recordings / name, scoring=config.ddpg.scoring, properties=keys)
        reseal(folder)  # as `lonlib record` reseals: the replay of the recording is tested

    recorded(a, a, "right.rrd")
    report = verify_experiment(folder)
    assert report.ok and report.recordings == 1
    different = [
        (r.b_fitness, r.b_end_step) != (a.b_fitness, a.b_end_step) for _, r in rows.iterrows()
    ]
    other = rows[different].iloc[0] if any(different) else b
    recorded(other, a, "wrong.rrd")
    report = verify_experiment(folder)
    assert (other.b_fitness, other.b_end_step) != (a.b_fitness, a.b_end_step)
    assert [f.check for f in report.errors] == ["recording"]
    assert "wrong.rrd shows another episode" in report.errors[0].message


def test_a_lost_or_unusable_actor_of_any_trial_is_an_error(damaged):
    # Since every trial's Actor is stored, a missing one is damage, accepted or not (older
    # experiments, which kept accepted optima only, get a warning: see the version test).
    folder, trials = damaged
    lost, broken = trials.iloc[1], trials.iloc[2]
    optimum_path(folder, lost.p, int(lost.run), int(lost["index"])).unlink()
    path = optimum_path(folder, broken.p, int(broken.run), int(broken["index"]))
    with np.load(path) as data:
        arrays = dict(data)
    arrays["theta"][3] = np.nan
    np.savez(path, **arrays)
    report = verify_experiment(folder)
    found = {(f.check, f.run, f.index, f.severity) for f in report.findings}
    assert ("actor", int(lost.run), int(lost["index"]), "error") in found
    assert ("actor", int(broken.run), int(broken["index"]), "error") in found
    assert report.replayed == len(trials) - 2  # the others are still checked


def test_an_end_step_that_cannot_carry_the_fitness_is_an_error(damaged):
    folder, trials = damaged
    scored = trials[trials["fitness"] > 0.1].iloc[0]

    def damage(table):
        at = table.index[table["index"] == int(scored["index"])][0]
        table.loc[at, "b_end_step"] = 1

    rewrite(folder, float(scored.p), int(scored.run), damage)
    found = {(f.check, f.index) for f in verify_experiment(folder).errors}
    assert ("consistency", int(scored["index"])) in found


def test_a_start_fitness_that_its_rebuilt_start_does_not_score_is_an_error(damaged):
    """The first search starts from the run's random Actor, a later one from its stored
    parent perturbed with the trial's stream: a changed start fitness, or a parent that is
    not the one the search started from, is named."""
    folder, trials = damaged
    run = trials[(trials.parent >= 0)].iloc[0]
    p, r = float(run.p), int(run.run)
    own = trials[(trials.p == p) & (trials.run == r)].set_index("index")
    later = next(i for i in own.index if own.parent[i] > 0)  # its grandparent scores less
    assert own.fitness[own.parent[own.parent[later]]] != own.start_fitness[later]

    def damage(table):
        table.loc[table["index"] == 0, "start_fitness"] += 0.025
        table.loc[table["index"] == later, "parent"] = int(own.parent[own.parent[later]])

    rewrite(folder, p, r, damage)
    found = {(f.check, f.index) for f in verify_experiment(folder, recordings=False).errors}
    assert ("start", 0) in found and ("start", later) in found


def test_a_robust_experiment_rescored_with_its_robust_mean_keeps_its_claims(robust_experiment):
    """Sampled with the robust fitness, the LON re-scored with each node's replayed robust
    mean is the LON itself: the same claims, written beside the nominal ones."""
    from lonlib.analysis.pipeline import analyse

    _, out, _ = robust_experiment
    result = analyse(out, close_figures=True)
    pd.testing.assert_frame_equal(result.claims_robust, result.claims)
    table = result.claims_side_by_side
    assert list(table["verdict (robust)"]) == list(table["verdict (nominal)"])
    written = {path.name for path in result.files}
    assert {"claims_robust.csv", "claims_nominal_robust.csv", "claims_nominal_robust.md"} <= written


def test_analyse_rescores_with_the_replayed_robust_means_and_pastes_them(
    robust_experiment, tmp_path, monkeypatch
):
    """`lonlib analyse --docs` on an experiment whose replayed robust means differ from the
    stored fitness (halved here): the robust claims are those of the LON re-scored with
    them, beside the nominal ones in the files and the page."""
    import io

    from lonlib.analysis import pipeline
    from lonlib.analysis.claims import claims_from_trials
    from lonlib.analysis.claims_report import README_BEGIN as CLAIMS_BEGIN
    from lonlib.analysis.claims_report import README_END as CLAIMS_END
    from lonlib.analysis.claims_rescored import (
        README_BEGIN,
        README_END,
        rescore_trials,
        side_by_side_markdown,
    )
    from lonlib.analysis.holding import README_BEGIN as HOLDING_BEGIN
    from lonlib.analysis.holding import README_END as HOLDING_END
    from lonlib.analysis.holding import holding_markdown, holding_summary, holding_table
    from lonlib.analysis.summary import README_BEGIN as SUMMARY_BEGIN
    from lonlib.analysis.summary import README_END as SUMMARY_END

    _, stored, trials = robust_experiment
    out = tmp_path / "copy"
    shutil.copytree(stored, out)
    real = pipeline.replay_optima
    halved = []

    def replay_halved(*args, **kwargs):
        replayed = real(*args, **kwargs)
        halved.append(replayed.assign(robust_mean=replayed["robust_mean"] / 2))
        return halved[-1]

    monkeypatch.setattr(pipeline, "replay_optima", replay_halved)
    page = tmp_path / "results.md"
    page.write_text(
        f"{SUMMARY_BEGIN}\n{SUMMARY_END}\n{CLAIMS_BEGIN}\n{CLAIMS_END}\n"
        f"{README_BEGIN}\nformer\n{README_END}\n{HOLDING_BEGIN}\nstale\n{HOLDING_END}\n"
    )
    cli_main(["analyse", str(out), "--docs", str(page)])
    figures = out / "figures"
    want = claims_from_trials(rescore_trials(trials, halved[0]))

    def read_back(frame: pd.DataFrame) -> pd.DataFrame:
        return pd.read_csv(io.StringIO(frame.to_csv(index=False)))

    robust = pd.read_csv(figures / "claims_robust.csv")
    pd.testing.assert_frame_equal(robust, read_back(want))
    assert not robust.equals(pd.read_csv(figures / "claims.csv"))
    side = pd.read_csv(figures / "claims_nominal_robust.csv")
    assert list(side["verdict (robust)"]) == list(want["verdict"])
    nominal = pd.read_csv(figures / "claims.csv")
    assert list(side["verdict (nominal)"]) == list(nominal["verdict"])
    pasted = page.read_text()
    assert f"{side_by_side_markdown(side).strip()}\n{README_END}" in pasted
    assert "former" not in pasted
    # the optima that hold: a row per accepted optimum, its block pasted from the CSV
    holding = pd.read_csv(figures / "holding.csv")
    assert len(holding) == int(trials["accepted"].sum()) > 0
    assert f"{holding_markdown(holding_summary(holding)).strip()}\n{HOLDING_END}" in pasted
    assert "stale" not in pasted
    # replayed from the experiment's own nominal start (eval_seed 3, start noise 0.05)
    config, _ = pipeline.load_experiment(out)
    own = holding_table(out, trials, config.env, config.ddpg.scoring)
    pd.testing.assert_frame_equal(holding, read_back(own))
    assert not own.equals(holding_table(out, trials, config.env))  # eval_seed 0's start
