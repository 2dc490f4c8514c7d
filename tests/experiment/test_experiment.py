"""Experiments: storage, resume after SIGKILL, executors agree, corrupt files, bad input."""

import dataclasses
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest

from lonlib.cli import main as cli_main
from lonlib.config import ExperimentConfig, load_config, named_config
from lonlib.experiment.running import run_experiment, status
from lonlib.storage.atomic import CorruptDataError
from lonlib.storage.layout import history_path, optimum_path, trials_path
from lonlib.storage.trials import read_optimum, read_trials
from lonlib.task.behaviour import LABELS, describe, descriptors_of
from tests.conftest import reseal, write_tiny_yaml

COMPARED = [
    *("p", "run", "index", "parent", "fitness", "accepted", "env_steps"),
    *("start_fitness", "improved", "stop_reason", "label", "b_turns_0", "b_robust_mean"),
]


@pytest.fixture(scope="module")
def reference(tiny_experiment):
    return tiny_experiment


def test_serial_run_stores_trials_optima_and_manifest(reference):
    config, out, trials = reference
    assert set(trials["p"]) == {1e-3, 1e-4} and set(trials["run"]) == {0, 1}
    assert trials["fitness"].nunique() > 1  # the tiny task is not a flat zero
    for row in trials[trials["accepted"]].itertuples():
        optimum = read_optimum(optimum_path(out, row.p, row.run, row.index))
        assert optimum.fitness == row.fitness
        assert optimum.theta.dtype.name == "float32"
    for row in trials.itertuples():
        history = pd.read_parquet(history_path(out, row.p, row.run, row.index))
        assert history["env_steps"].iloc[-1] <= row.env_steps and len(history) > 1
    manifest = (out / "manifest.json").read_text()
    for key in ("git_commit", "versions", "torch", "created", "lonlib_version"):
        assert key in manifest
    table = status(out)
    assert list(table["finished"]) == [2, 2] and list(table["not_started"]) == [0, 0]


def test_every_trial_stores_its_behaviour_and_the_start_it_came_from(reference):
    config, out, trials = reference
    assert trials["label"].isin(LABELS).all() and trials["b_end_step"].gt(0).all()
    assert trials["start_fitness"].notna().all() and trials["stop_reason"].eq("budget").all()
    assert (trials["improved"] == (trials["fitness"] > trials["start_fitness"])).all()
    stored = descriptors_of(trials)
    for row, descriptor in zip(trials.itertuples(), stored, strict=True):
        assert descriptor.fitness == row.fitness  # the descriptor is the scored episode's
        # every trial's Actor is stored, and a fresh rollout of it gives the stored descriptor
        optimum = read_optimum(optimum_path(out, row.p, row.run, row.index))
        fresh = describe(optimum.theta, config.env, config.ddpg.scoring)
        np.testing.assert_equal(dataclasses.asdict(fresh), dataclasses.asdict(descriptor))


def test_only_result_changing_settings_must_match_to_resume(reference, tmp_path):
    config, out, trials = reference
    elsewhere = dataclasses.replace(
        config, ddpg=dataclasses.replace(config.ddpg, threads=2, device="cpu:0")
    )
    again = run_experiment(elsewhere, out, progress=False)
    pd.testing.assert_frame_equal(again[COMPARED], trials[COMPARED])
    changed = dataclasses.replace(config, ddpg=dataclasses.replace(config.ddpg, batch_size=16))
    with pytest.raises(ValueError, match="different configuration") as refused:
        run_experiment(changed, out, progress=False)
    assert "--allow-change" not in str(refused.value)  # only max_local_searches may change


def test_rerun_resumes_and_redoes_nothing(reference):
    config, out, trials = reference
    stamps = {p: p.stat().st_mtime_ns for p in out.rglob("*.parquet")}
    again = run_experiment(config, out, progress=False)
    pd.testing.assert_frame_equal(again[COMPARED], trials[COMPARED])
    assert stamps == {p: p.stat().st_mtime_ns for p in out.rglob("*.parquet")}


@pytest.mark.parametrize(("workers", "scheduler"), [(2, None), (2, "dask-local")])
def test_process_pool_and_dask_give_identical_trials(reference, tmp_path, workers, scheduler):
    config, _, trials = reference
    other = run_experiment(
        config, tmp_path / "out", workers=workers, scheduler=scheduler, progress=False
    )
    pd.testing.assert_frame_equal(other[COMPARED], trials[COMPARED])


@pytest.fixture(scope="module")
def longer_searches(tmp_path_factory):
    """The tiny experiment with 300-step searches, of its first p only, run serially: (YAML
    path, trials); long enough to be killed part-way (two runs of four such searches)."""
    folder = tmp_path_factory.mktemp("longer")
    yaml_path = write_tiny_yaml(folder, max_steps=300)
    text = yaml_path.read_text()
    assert "perturbations: [1.0e-3, 1.0e-4]" in text
    yaml_path.write_text(text.replace("[1.0e-3, 1.0e-4]", "[1.0e-3]"))
    return yaml_path, run_experiment(load_config(yaml_path), folder / "serial", progress=False)


def test_sigkill_then_resume_gives_the_uninterrupted_trials(longer_searches, tmp_path):
    yaml_path, expected = longer_searches
    config = load_config(yaml_path)
    out = tmp_path / "killed"
    command = [sys.executable, "-m", "lonlib", "run", str(yaml_path), "--out", str(out), "--quiet"]
    process = subprocess.Popen(command, start_new_session=True)
    first = trials_path(out, 1e-3, 0)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if first.exists() and len(read_trials(first)) >= 2:
            break
        time.sleep(0.05)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    partial = read_trials(first)
    assert len(partial) >= 2 and len(expected) > len(partial)
    resumed = run_experiment(config, out, progress=False)
    pd.testing.assert_frame_equal(resumed[COMPARED], expected[COMPARED])
    assert not list(out.rglob("*.tmp"))


def test_corrupt_file_is_named_and_nothing_else_is_touched(reference, tmp_path):
    config, out, _ = reference
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-r", str(out), str(copy)], check=True)
    damaged = trials_path(copy, 1e-4, 1)
    damaged.write_bytes(damaged.read_bytes()[:40])
    before = {p: p.read_bytes() for p in copy.rglob("*") if p.is_file()}
    with pytest.raises(CorruptDataError, match=str(damaged)):
        run_experiment(config, copy, progress=False)
    with pytest.raises(CorruptDataError, match="run_0001"):
        status(copy)
    assert before == {p: p.read_bytes() for p in copy.rglob("*") if p.is_file()}


@pytest.mark.parametrize(
    ("yaml_text", "message"),
    [
        ("perturbations: [0.0]", "perturbations"),
        ("perturbations: [-1.0e-3]", "perturbations"),
        ("runs: 0", "runs"),
        ("tolerance: 0", "tolerance"),
        ("colour: red", "colour"),
        ("env: {n_carts: 7}", "n_carts"),
        ("env: {n_cart: 2}", "n_cart"),
        ("ddpg: {batch_size: 0}", "batch_size"),
        ("ddpg: {lr: 0.1}", "lr"),
        ("perturbations: [abc]", "perturbations"),
    ],
)
def test_bad_configuration_is_refused_before_any_compute(tmp_path, yaml_text, message):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml_text)
    with pytest.raises(ValueError, match=message):
        load_config(path)


def test_folder_with_another_experiment_is_refused(reference, tmp_path):
    config, out, _ = reference
    other = ExperimentConfig.from_mapping({**config.to_dict(), "seed": 7})
    with pytest.raises(ValueError, match="seed"):
        run_experiment(other, out, progress=False)


def test_named_configurations():
    quick, paper = named_config("quick"), named_config("paper")
    assert quick.perturbations == paper.perturbations == (1e-3, 1e-4)
    assert paper.runs == 100 and paper.tolerance == 5 and paper.env.steps == 2000
    assert quick.ddpg.max_steps < paper.ddpg.max_steps and "not the paper" in quick.note
    with pytest.raises(ValueError, match="nonsense"):
        load_config("nonsense")


def test_cli_lon_prints_metrics_and_writes_exports(reference, tmp_path, capsys):
    _, out, _ = reference
    cli_main(["lon", str(out), "--full", "--out", str(tmp_path / "lon")])
    printed = capsys.readouterr().out
    assert "global_sinks" in printed and "funnels" in printed
    names = {p.name for p in (tmp_path / "lon").iterdir()}
    assert {"metrics.csv", "lon_p=0.0001_full.trace", "lon_p=0.001_full.graphml"} <= names
    with pytest.raises(SystemExit):
        cli_main(["run", "quick", "--p", "0"])


def test_a_killed_pool_worker_is_retried_and_its_run_resumes(longer_searches, tmp_path):
    import threading

    import psutil

    yaml_path, expected = longer_searches
    config = load_config(yaml_path)
    out = tmp_path / "pool"
    outcome = {}

    def run() -> None:
        try:
            outcome["trials"] = run_experiment(config, out, workers=2, progress=False)
        except Exception as error:  # surfaced by the assertion below
            outcome["error"] = error

    thread = threading.Thread(target=run)
    thread.start()
    deadline = time.monotonic() + 120
    killed = None
    while killed is None and time.monotonic() < deadline:
        if any(len(read_trials(p)) >= 1 for p in out.glob("p=*/run_*/trials.parquet")):
            workers = [
                child
                for child in psutil.Process().children(recursive=True)
                if "multiprocessing" in " ".join(child.cmdline())
                and "resource_tracker" not in " ".join(child.cmdline())
            ]
            if workers:
                workers[0].kill()
                killed = workers[0].pid
        time.sleep(0.05)
    thread.join(timeout=300)
    assert killed is not None, "no worker to kill"
    assert "error" not in outcome, outcome.get("error")
    pd.testing.assert_frame_equal(outcome["trials"][COMPARED], expected[COMPARED])


def test_a_trials_table_from_an_older_lonlib_is_named_as_such(tmp_path):
    from lonlib.storage.trials import read_trials

    old = tmp_path / "trials.parquet"
    columns = ["p", "run", "index", "parent", "fitness", "accepted", "seconds", "env_steps"]
    pd.DataFrame([[1e-4, 0, 0, -1, 0.0, True, 1.0, 10]], columns=columns).to_parquet(old)
    with pytest.raises(CorruptDataError, match="older lonlib"):
        read_trials(old)


def test_rerunning_a_finished_experiment_changes_no_file(tiny_experiment):
    config, folder, _ = tiny_experiment
    before = {p: p.read_bytes() for p in folder.rglob("*") if p.is_file() and p.name != ".lock"}
    run_experiment(config, folder, progress=False, executor="lockstep")
    after = {p: p.read_bytes() for p in folder.rglob("*") if p.is_file() and p.name != ".lock"}
    assert after == before


def _truncated_copy(out, tmp_path, keep, longer=None):
    """A copy of the experiment ``out`` whose runs keep only their first ``keep`` trials (as
    a run interrupted after them stores it: the trials table is the source of truth), but
    the runs of ``longer`` (a mapping ``(p, run) -> count``) keep that many."""
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    for path in copy.glob("p=*/run_*/trials.parquet"):
        table = read_trials(path)
        key = (float(table["p"].iloc[0]), int(table["run"].iloc[0]))
        table.iloc[: (longer or {}).get(key, keep)].to_parquet(path)
    return reseal(copy)


def _reject(folder, p, run, indices):
    """Store the trials ``indices`` of run ``(p, run)`` as rejected (their parent stays)."""
    path = trials_path(folder, p, run)
    table = read_trials(path)
    table.loc[table["index"].isin(indices), "accepted"] = False
    table.to_parquet(path)
    reseal(folder)


def test_a_lowered_local_search_budget_ends_the_runs_that_reach_it(reference, tmp_path, capsys):
    import json

    config, out, trials = reference
    copy = _truncated_copy(out, tmp_path, keep=2)
    yaml_path = write_tiny_yaml(tmp_path)
    text = yaml_path.read_text()
    yaml_path.write_text(text.replace("max_local_searches: 4", "max_local_searches: 2"))
    argv = ["run", str(yaml_path), "--out", str(copy), "--quiet"]
    with pytest.raises(SystemExit):
        cli_main(argv)
    assert "--allow-change max_local_searches" in capsys.readouterr().err
    cli_main([*argv, "--dry-run", "--allow-change", "max_local_searches"])
    assert "changing max_local_searches from 4 to 2" in capsys.readouterr().out
    cli_main([*argv, "--allow-change", "max_local_searches"])
    assert "8 local searches stored" in capsys.readouterr().out  # every run ended, none sampled
    manifest = json.loads((copy / "manifest.json").read_text())
    assert manifest["config"]["max_local_searches"] == 2
    assert manifest["sessions"][-1]["changed"] == {"max_local_searches": [4, 2]}
    assert list(status(copy)["finished"]) == [2, 2]
    # the stored settings now hold: the old budget is the change, and needs asking again
    with pytest.raises(ValueError, match="different configuration"):
        run_experiment(config, copy, progress=False)


def test_a_budget_below_a_stored_run_is_refused_naming_the_field_and_that_run(reference, tmp_path):
    config, out, trials = reference
    copy = _truncated_copy(out, tmp_path, keep=2, longer={(1e-3, 1): 4})
    too_low = dataclasses.replace(config, max_local_searches=3)
    before = (copy / "manifest.json").read_bytes()
    with pytest.raises(ValueError, match=r"max_local_searches 4 -> 3.*\(p=0.001, run 1: 4 local"):
        run_experiment(too_low, copy, progress=False, allow_changes=["max_local_searches"])
    with pytest.raises(ValueError) as refused:
        run_experiment(too_low, copy, progress=False, allow_changes=["max_local_searches"])
    assert str(refused.value).count("run ") == 1  # only the run that is too long
    assert (copy / "manifest.json").read_bytes() == before
    for bad in (["tolerance"], "max_local_searches", None):
        with pytest.raises(ValueError, match="allow_changes must"):
            run_experiment(config, copy, progress=False, allow_changes=bad)


def test_a_run_stored_past_its_end_is_refused_and_verify_names_it(reference, tmp_path):
    from lonlib.analysis.verify import algorithm_findings
    from lonlib.storage.trials import read_experiment_trials

    config, out, trials = reference
    copy = _truncated_copy(out, tmp_path, keep=4)
    _reject(copy, 1e-4, 0, [1, 2])  # T = 2 failures: the run ended after its third search
    with pytest.raises(ValueError, match=r"go on past where Algorithm 2.*p=0.0001, run 0: 4"):
        run_experiment(config, copy, progress=False)
    findings = algorithm_findings(config, read_experiment_trials(copy))
    assert {(f.p, f.run, f.index) for f in findings if "after the run ended" in f.message} == {
        (1e-4, 0, 3)
    }
    assert all(f.check == "algorithm" and (f.p, f.run) == (1e-4, 0) for f in findings)
    assert algorithm_findings(config, trials) == []


def test_a_raised_budget_continues_the_runs_the_budget_ended_not_those_t_ended(reference, tmp_path):
    config, out, trials = reference
    copy = _truncated_copy(out, tmp_path, keep=4)
    _reject(copy, 1e-3, 1, [2, 3])  # this run ended by T = 2 exactly at the old budget
    raised = dataclasses.replace(config, max_local_searches=5)
    again = run_experiment(raised, copy, progress=False, allow_changes=["max_local_searches"])
    counts = again.groupby(["p", "run"]).size()
    assert counts[(1e-3, 1)] == 4
    assert all(count == 5 for key, count in counts.items() if key != (1e-3, 1))
    first = again[again["index"] < 4].reset_index(drop=True)
    unchanged = first[(first["p"] != 1e-3) | (first["run"] != 1)].reset_index(drop=True)
    expected = trials[(trials["p"] != 1e-3) | (trials["run"] != 1)].reset_index(drop=True)
    pd.testing.assert_frame_equal(unchanged[COMPARED], expected[COMPARED])


@pytest.mark.parametrize("other", ["a sampling session", "an older lonlib holding run 0"])
def test_a_budget_change_is_refused_while_another_process_samples(reference, tmp_path, other):
    from lonlib.experiment.runs import hold_runs
    from lonlib.storage.layout import SAMPLING_LOCK
    from lonlib.storage.lock import SamplingLock

    config, out, trials = reference
    copy = _truncated_copy(out, tmp_path, keep=2)
    before = (copy / "manifest.json").read_bytes()
    lowered = dataclasses.replace(config, max_local_searches=2)
    sampling = SamplingLock(copy / SAMPLING_LOCK)
    with hold_runs(copy, [(1e-3, 0)] if other != "a sampling session" else []) as held:
        assert held
        if other == "a sampling session":
            sampling.acquire(exclusive=False)
        with pytest.raises(ValueError, match="another process is sampling"):
            run_experiment(lowered, copy, progress=False, allow_changes=["max_local_searches"])
        sampling.release()
    assert (copy / "manifest.json").read_bytes() == before
    run_experiment(lowered, copy, progress=False, allow_changes=["max_local_searches"])


def test_an_empty_trials_table_ends_no_run_early(reference, tmp_path):
    from lonlib.storage.trials import runs_ending_early

    config, out, trials = reference
    copy = _truncated_copy(out, tmp_path, keep=4, longer={(1e-4, 1): 0})
    assert runs_ending_early(copy, config.basin_hopping) == []
    assert runs_ending_early(copy, dataclasses.replace(config, max_local_searches=3).basin_hopping)


def test_a_session_lets_go_of_the_folder_however_its_end_fails(reference, tmp_path, monkeypatch):
    import lonlib.storage.session as session
    from lonlib.storage.layout import SAMPLING_LOCK
    from lonlib.storage.lock import SamplingLock

    config, out, trials = reference
    copy = _truncated_copy(out, tmp_path, keep=2)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(session, "_record_session_end", interrupted)
    lowered = dataclasses.replace(config, max_local_searches=2)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(lowered, copy, progress=False, allow_changes=["max_local_searches"])
    other = SamplingLock(copy / SAMPLING_LOCK)
    other.acquire(exclusive=True)  # LockHeld if the session still held it
    other.release()
