"""A Gymnasium task through the public path: ``run_experiment`` samples it, ``verify``
replays it, ``analyse`` draws what applies and says what it skips, and an environment that
fails mid-run stops the run with its name while what was stored stays."""

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest

from lonlib.analysis import analyse
from lonlib.analysis.verify import verify_experiment
from lonlib.config import ExperimentConfig
from lonlib.experiment import run_experiment
from lonlib.storage.trials import read_experiment_trials
from lonlib.task import TaskEnvironmentError
from tests.task.test_gymnasium_task import Line  # registers lonlib-test/Line-v0


def line_config(**task) -> ExperimentConfig:
    return ExperimentConfig.from_mapping(
        {
            "name": "line",
            "perturbations": [1e-3],
            "runs": 2,
            "tolerance": 1,
            "max_local_searches": 3,
            "task": {"gymnasium": "lonlib-test/Line-v0", "fitness_range": [-200, 0], **task},
            "ddpg": {
                "batch_size": 16,
                "buffer_size": 200,
                "warmup_steps": 20,
                "max_steps": 60,
                "min_steps": 0,
                "patience_steps": 1000,
            },
        }
    )


def test_a_gymnasium_experiment_samples_verifies_and_analyses(tmp_path):
    out = tmp_path / "line"
    trials = run_experiment(line_config(), out, progress=False)
    assert len(trials) >= 4 and trials["fitness"].between(0, 1).all()
    assert not any(c.startswith("b_") for c in trials.columns)  # no pendulum descriptors
    report = verify_experiment(out)
    assert report.ok and report.replayed == len(trials) and report.starts == len(trials)
    assert any(f.check == "task" and "bit for bit" in f.message for f in report.findings)
    result = analyse(out, close_figures=True)
    assert "the paper's claims a-e" in result.skipped and result.claims.empty
    names = {p.name for p in result.files}
    assert {"fig2_optima_boxplot.png", "fig3_lon_p=0.001.png", "metrics.csv"} <= names
    assert not (out / "figures" / "claims.csv").exists()


def test_recordings_show_the_scored_episode_with_frames_and_verify(tmp_path):
    from lonlib.analysis import record_optima
    from lonlib.analysis.recordings import recorded_entities, recording_properties

    out = tmp_path / "line"
    trials = run_experiment(line_config(), out, progress=False)
    paths = record_optima(out)
    assert paths
    for path in paths:
        props = recording_properties(path)
        stored = trials.set_index(["p", "run", "index"]).loc[
            (props["p"], props["run"], props["index"]), "fitness"
        ]
        assert props["fitness"] == stored and props["end_step"] == 20
        entities = recorded_entities(path)
        assert entities["/frames"] == 20 and entities["/actions"] == 20
    report = verify_experiment(out)
    assert report.ok and report.recordings == len(paths)


def test_a_stored_fitness_that_does_not_replay_is_an_error(tmp_path):
    out = tmp_path / "line"
    run_experiment(line_config(), out, progress=False)
    # the same folder verified as another task: the Actors score differently there
    import json

    manifest = json.loads((out / "manifest.json").read_text())
    manifest["config"]["task"]["fitness_range"] = [-100, 0]
    (out / "manifest.json").write_text(json.dumps(manifest))
    from tests.conftest import reseal

    reseal(out)
    report = verify_experiment(out)
    assert not report.ok and {f.check for f in report.errors} >= {"fitness", "start"}


def test_sampled_elsewhere_the_replay_is_within_a_tolerance_and_a_miss_is_a_warning(tmp_path):
    import json

    from tests.conftest import reseal

    out = tmp_path / "line"
    run_experiment(line_config(), out, progress=False)
    manifest = json.loads((out / "manifest.json").read_text())
    session = manifest["sessions"][0]
    assert session["task_environment"]["entry_point"].endswith(":Line")
    session["task_environment"]["gymnasium"] = "0.29.1"  # sampled with another Gymnasium
    (out / "manifest.json").write_text(json.dumps(manifest))
    reseal(out)
    report = verify_experiment(out)
    assert report.ok and any("replayed within 1e-09" in f.message for f in report.findings)
    manifest["config"]["task"]["fitness_range"] = [-100, 0]  # now every fitness misses
    (out / "manifest.json").write_text(json.dumps(manifest))
    reseal(out)
    report = verify_experiment(out)
    assert report.ok and {f.check for f in report.warnings} >= {"fitness", "start"}


def test_a_run_is_the_same_serially_and_resumed(tmp_path):
    config = line_config()
    whole = run_experiment(config, tmp_path / "whole", progress=False)
    part = dataclasses.replace(config, max_local_searches=1)
    run_experiment(part, tmp_path / "part", progress=False)
    resumed = run_experiment(
        config, tmp_path / "part", progress=False, allow_changes=("max_local_searches",)
    )
    columns = ["p", "run", "index", "parent", "fitness", "accepted", "start_fitness"]
    assert whole[columns].equals(resumed[columns])


def test_an_environment_failing_mid_run_names_the_run_and_keeps_what_was_stored(
    tmp_path, monkeypatch
):
    out = tmp_path / "line"
    config = line_config()
    run_experiment(dataclasses.replace(config, max_local_searches=1), out, progress=False)
    before = read_experiment_trials(out)
    # the runs continue in an environment that now fails at its third step
    monkeypatch.setattr(Line, "FAULT", "raise")
    with pytest.raises(TaskEnvironmentError) as error:
        run_experiment(config, out, progress=False, allow_changes=("max_local_searches",))
    text = str(error.value)
    assert "run (p=0.001, run=0)" in text and "ValueError: contact solver diverged" in text
    after = read_experiment_trials(out)
    np.testing.assert_array_equal(after["fitness"], before["fitness"])


def test_a_gymnasium_task_gives_the_same_trials_on_dask_and_in_lockstep_processes(tmp_path):
    """Worker processes (Dask's, as a process pool's, as lockstep batches') make the task
    themselves."""
    config = ExperimentConfig.from_mapping(
        {
            **line_config().to_dict(),
            "task": {
                "gymnasium": "Pendulum-v1",
                "fitness_range": [-3254.72, 0],
                "episode_steps": 40,
            },
        }
    )
    serial = run_experiment(config, tmp_path / "serial", progress=False)
    other = run_experiment(
        config, tmp_path / "other", workers=2, scheduler="dask-local", progress=False
    )
    columns = ["p", "run", "index", "parent", "fitness", "accepted", "start_fitness"]
    assert serial[columns].equals(other[columns])
    # and one lockstep batch per worker process (each makes the task and its vector env)
    batches = run_experiment(
        config, tmp_path / "batches", workers=2, executor="lockstep", slots=1, progress=False
    )
    assert serial[columns].equals(batches[columns])


@pytest.mark.parametrize("name", ["pendulum-v1", "mountaincar-continuous"])
def test_the_committed_worked_example_replays_through_the_public_path(name):
    """A sample of the committed optima: each stored Actor's greedy episode gives its stored
    fitness, bit for bit where the manifest's CPU dispatch and environment match this
    machine's (else within verify's tolerance)."""
    from pathlib import Path

    from lonlib.analysis.pipeline import load_experiment
    from lonlib.analysis.verify import TASK_REPLAY_TOLERANCE, task_replays_exactly
    from lonlib.storage.layout import optimum_path
    from lonlib.storage.trials import read_optimum
    from lonlib.task import task_of

    folder = Path(__file__).parents[2] / "data" / "gymnasium" / name
    if not (folder / "manifest.json").exists():
        pytest.skip(f"{folder} is not committed yet")
    config, trials = load_experiment(folder)
    task = task_of(config)
    exact = task_replays_exactly(folder, config)
    sample = trials.sort_values("fitness").iloc[:: max(1, len(trials) // 6)]
    for row in sample.itertuples():
        theta = read_optimum(optimum_path(folder, row.p, row.run, row.index)).theta
        replayed = float(task.fitness(theta[None])[0])
        if exact:
            assert replayed == row.fitness
        else:
            assert abs(replayed - row.fitness) <= TASK_REPLAY_TOLERANCE


def test_verify_gymnasium_on_a_gymnasium_task_says_it_applies_to_the_pendulums_only(
    tmp_path, capsys
):
    """``--gymnasium`` replays the pendulums' registered env; on a Gymnasium task (whose
    plain verify already replays through gymnasium.make) it says so and keeps the result."""
    from lonlib.cli import main as cli_main

    out = tmp_path / "line"
    run_experiment(line_config(), out, progress=False)
    cli_main(["verify", "--gymnasium", "--no-recordings", str(out)])
    printed = capsys.readouterr().out
    assert "verify: OK" in printed
    assert "info: [gymnasium]" in printed and "plain verify" in printed


def test_lockstep_gives_a_gymnasium_task_the_serial_trials_and_drains(tmp_path):
    """Three runs in lockstep batches of two slots (runs refill the slot a run ends in), a
    first call drained at once and a second to the end: bit for bit the serial trials."""
    from tests.experiment.test_drain import assert_same, snapshot

    config = dataclasses.replace(line_config(), runs=3)
    run_experiment(config, tmp_path / "serial", progress=False)
    out = tmp_path / "lockstep"
    lockstep = {"progress": False, "executor": "lockstep", "slots": 2}
    drained = run_experiment(config, out, drain_after_seconds=0, **lockstep)
    assert len(drained) == 2  # the first fill's searches, stored; nothing started after
    run_experiment(config, out, **lockstep)
    assert_same(snapshot(out), snapshot(tmp_path / "serial"))
    assert verify_experiment(out).ok


def test_an_environment_failing_in_a_lockstep_batch_names_its_run(tmp_path, monkeypatch):
    out = tmp_path / "line"
    config = line_config()
    run_experiment(dataclasses.replace(config, max_local_searches=1), out, progress=False)
    before = read_experiment_trials(out)
    monkeypatch.setattr(Line, "FAULT", "nan-observation")
    with pytest.raises(TaskEnvironmentError) as error:
        run_experiment(
            config, out, progress=False, executor="lockstep", allow_changes=("max_local_searches",)
        )
    text = str(error.value)
    assert text.startswith("run (p=0.001, run=0), local search 1: local search: ")
    assert "non-finite observation at step 3:" in text and "1 stored" in text
    np.testing.assert_array_equal(read_experiment_trials(out)["fitness"], before["fitness"])


def test_a_task_descriptor_is_stored_replayed_and_grouped_by(tmp_path):
    """``task.descriptor``: every optimum stores its ``b_*`` values and label, in serial and
    in lockstep alike; verify replays them (an edited value is an error); the analysis
    groups optima by the label."""
    import json

    from tests.conftest import reseal

    descriptor = "tests.task.test_gymnasium_behaviour:line_position"
    config = line_config(descriptor=descriptor)
    out = tmp_path / "line"
    trials = run_experiment(config, out, progress=False)
    assert {"b_end_distance", "b_steps", "label"} <= set(trials.columns)
    assert (trials["b_steps"] == 20).all() and set(trials["label"]) <= {"near", "far"}
    lockstep = run_experiment(config, tmp_path / "lockstep", executor="lockstep", progress=False)
    assert trials.drop(columns="seconds").equals(lockstep.drop(columns="seconds"))
    report = verify_experiment(out)
    assert report.ok and any(f.check == "descriptor" for f in report.findings)
    result = analyse(out, close_figures=True)
    assert set(result.behaviours["label"]) == set(trials["label"])
    path = next(out.glob("p=*/run_0000/trials.parquet"))
    stored = pd.read_parquet(path)
    flipped = "far" if stored.loc[0, "label"] == "near" else "near"
    for column, value in (("label", flipped), ("b_steps", 19.0)):
        table = stored.copy()
        table.loc[0, column] = value
        table.to_parquet(path)
        reseal(out)  # as if lonlib had written it: the replay, not the seal, must find it
        report = verify_experiment(out)
        assert not report.ok and [f.check for f in report.errors] == ["descriptor"], column
        assert column in report.errors[0].message
    assert json.loads((out / "manifest.json").read_text())["config"]["task"]["descriptor"]


def folder_bytes(out) -> dict:
    """Every file of ``out`` but the lock files (a run's lock names its last holder)."""
    files = [p for p in sorted(out.rglob("*")) if p.is_file() and not p.name.endswith(".lock")]
    return {p.relative_to(out): p.read_bytes() for p in files}


SWITCHABLE = "tests.task.test_gymnasium_behaviour:switchable"


def test_a_bad_descriptor_is_refused_before_any_compute_or_folder(tmp_path, monkeypatch):
    """A descriptor with a wrong return is one line naming ``task.descriptor`` when the run
    starts (the pre-flight describes a random Actor's episode), not after a local search."""
    import lonlib.experiment.running as running

    def no_search(config):
        raise AssertionError("a local search was started")

    monkeypatch.setattr(running, "experiment_local_search", no_search)
    out = tmp_path / "line"
    config = line_config(descriptor="tests.task.test_gymnasium_behaviour:broken")
    with pytest.raises(ValueError) as error:
        run_experiment(config, out, progress=False)
    assert str(error.value).startswith("task.descriptor (tests.task.test_gymnasium_behaviour")
    assert "spread must be a finite number" in str(error.value) and "\n" not in str(error.value)
    assert not out.exists()


def test_a_descriptor_giving_other_names_on_resume_stops_and_writes_nothing(tmp_path, monkeypatch):
    """Stored trials keep the columns they were sampled with: a descriptor whose code now
    gives other names is refused before any compute when the session starts, and, should a
    run get past that (a process that never checked), before its trial is saved, serially
    and in lockstep alike, for a resumed run and for a new run of the experiment."""
    import lonlib.experiment.runs as runs
    from lonlib.experiment.lockstep import run_lockstep
    from lonlib.experiment.running import run_one
    from tests.task import test_gymnasium_behaviour as descriptors

    out = tmp_path / "line"
    config = line_config(descriptor=SWITCHABLE)
    run_experiment(dataclasses.replace(config, max_local_searches=1, runs=1), out, progress=False)
    assert "b_end_distance" in read_experiment_trials(out)
    before = folder_bytes(out)
    monkeypatch.setattr(descriptors, "NAMES", ["distance_at_end"])
    with pytest.raises(ValueError) as error:  # the session's check, before any compute
        run_experiment(config, out, progress=False, allow_changes=("max_local_searches",))
    text = str(error.value)
    assert text.startswith(f"task.descriptor ({SWITCHABLE}) now gives the columns")
    assert "['b_end_distance']" in text and "\n" not in text
    assert folder_bytes(out) == before
    # a worker process that made its own task: the check before each save
    for call, run, whose in [
        (lambda: run_one(out, config, 1e-3, 0), 0, "the run's stored trials"),
        (lambda: run_one(out, config, 1e-3, 1), 1, "the experiment's stored trials"),
        (lambda: run_lockstep(out, config, [(1e-3, 0)], lambda summary: None, 1), 0, "run's"),
    ]:
        monkeypatch.setattr(runs, "_TASKS", {})  # a new process: nothing described yet
        with pytest.raises(ValueError) as error:
            call()
        text = str(error.value)
        assert text.startswith(f"run (p=0.001, run={run}): task.descriptor ({SWITCHABLE})")
        assert whose in text and "\n" not in text
        assert folder_bytes(out) == before


def test_a_lockstep_batch_that_fails_closes_its_environments(tmp_path, monkeypatch):
    from tests.ddpg.test_gymnasium_search import Tracked

    out = tmp_path / "tracked"
    config = line_config(gymnasium="lonlib-test/Tracked-v0")
    lockstep = {"progress": False, "executor": "lockstep"}
    run_experiment(dataclasses.replace(config, max_local_searches=1), out, **lockstep)
    open_before = set(Tracked.OPEN)  # the task's own environment (for greedy episodes)
    monkeypatch.setattr(Line, "FAULT", "raise")  # the training environments now fail
    with pytest.raises(TaskEnvironmentError):
        run_experiment(config, out, allow_changes=("max_local_searches",), **lockstep)
    assert open_before == Tracked.OPEN


def test_a_hand_edited_manifest_is_named_before_the_descriptor_is_compared(tmp_path):
    """A descriptor written into a sealed folder's manifest by hand is the manifest's
    tampering (named by the digest check), not a descriptor that changed its names."""
    from lonlib.storage.digests import TamperedDataError

    out = tmp_path / "line"
    config = line_config()
    run_experiment(dataclasses.replace(config, max_local_searches=1, runs=1), out, progress=False)
    manifest = json.loads((out / "manifest.json").read_text())
    manifest["config"]["task"]["descriptor"] = SWITCHABLE
    (out / "manifest.json").write_text(json.dumps(manifest))
    before = folder_bytes(out)
    with pytest.raises(TamperedDataError) as error:
        run_experiment(line_config(descriptor=SWITCHABLE), out, progress=False)
    assert "manifest.json" in str(error.value) and "descriptor" not in str(error.value)
    assert folder_bytes(out) == before
    (out / "seal.json").unlink()  # its runs' digests still say it was sealed
    with pytest.raises(TamperedDataError) as error:
        run_experiment(line_config(descriptor=SWITCHABLE), out, progress=False)
    assert "seal.json" in str(error.value) and "descriptor" not in str(error.value)
