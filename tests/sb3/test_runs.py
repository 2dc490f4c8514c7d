"""An experiment with an SB3 local search: two critics in its random start, a basin-hopping
run killed (SIGKILL) in the middle of a local search and resumed to the trials of an
uninterrupted run, ``lonlib verify`` OK; a missing Stable-Baselines3 refused in one line
naming the extra, before any compute."""

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
from lonlib.config import load_config
from lonlib.experiment.running import run_experiment
from lonlib.experiment.runs import experiment_task, initial_parameters
from lonlib.sb3 import check_search
from lonlib.storage.layout import optimum_path, trials_path
from lonlib.storage.trials import read_optimum, read_trials

YAML = """
name: pendulum-sb3-td3
perturbations: [0.01]
runs: 1
tolerance: 2
max_local_searches: 3
task: {gymnasium: Pendulum-v1, fitness_range: [-800, 0], episode_steps: 100, search: sb3-td3}
ddpg: {batch_size: 32, buffer_size: 1000, warmup_steps: 200, max_steps: 500, min_steps: 500,
       patience_steps: 1000}
"""
COMPARED = ["p", "run", "index", "parent", "fitness", "accepted", "env_steps", "start_fitness"]


def write_yaml(folder, search: str = "sb3-td3"):
    path = folder / f"{search}.yaml"
    path.write_text(YAML.replace("sb3-td3", search))
    return path


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """(YAML path, config, output folder, trials) of the SB3-TD3 experiment run whole."""
    folder = tmp_path_factory.mktemp("sb3")
    path = write_yaml(folder)
    config = load_config(path)
    return path, config, folder / "out", run_experiment(config, folder / "out", progress=False)


def test_the_random_start_of_a_twin_critic_search_holds_two_critics(tmp_path):
    td3, ddpg = (load_config(write_yaml(tmp_path, s)) for s in ("sb3-td3", "sb3-ddpg"))
    size = experiment_task(td3).critic_spec.n_params
    (theta2, omega2), (theta1, omega1) = (
        initial_parameters(td3, 0.01, 0),
        initial_parameters(ddpg, 0.01, 0),
    )
    assert omega2.shape == (2 * size,) and omega1.shape == (size,)
    np.testing.assert_array_equal(theta2, theta1)
    np.testing.assert_array_equal(omega2[:size], omega1)  # the first critic is the one critic
    assert not np.array_equal(omega2[size:], omega1)


def test_a_run_killed_mid_search_resumes_to_the_uninterrupted_trials(uninterrupted, tmp_path):
    path, config, whole, expected = uninterrupted
    assert len(expected) == 3 and expected["fitness"].nunique() > 1
    out = tmp_path / "killed"
    command = [sys.executable, "-m", "lonlib", "run", str(path), "--out", str(out), "--quiet"]
    process = subprocess.Popen(command, start_new_session=True)
    first = trials_path(out, 0.01, 0)
    try:
        deadline = time.monotonic() + 120
        while not (first.exists() and len(read_trials(first)) >= 1):
            assert time.monotonic() < deadline and process.poll() is None
            time.sleep(0.02)
        time.sleep(0.5)  # into the second local search (each takes seconds)
    finally:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    assert len(read_trials(first)) == 1  # killed while the second search ran
    resumed = run_experiment(config, out, progress=False)
    pd.testing.assert_frame_equal(resumed[COMPARED], expected[COMPARED])
    for index in range(3):
        ours = read_optimum(optimum_path(out, 0.01, 0, index))
        theirs = read_optimum(optimum_path(whole, 0.01, 0, index))
        np.testing.assert_array_equal(ours.theta, theirs.theta)
        np.testing.assert_array_equal(ours.omega, theirs.omega)
        assert ours.omega.shape == (2 * experiment_task(config).critic_spec.n_params,)


def test_verify_replays_every_sb3_trial_and_start(uninterrupted, capsys):
    _, _, whole, _ = uninterrupted
    cli_main(["verify", str(whole), "--no-recordings"])
    printed = capsys.readouterr().out
    assert "3 replayed from their stored Actor, 3 starts rebuilt" in printed
    assert "verify: OK" in printed


@pytest.mark.parametrize("dry_run", [True, False])
def test_a_missing_sb3_is_one_line_naming_the_extra(tmp_path, monkeypatch, capsys, dry_run):
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # import fails, as uninstalled
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as stopped:
        cli_main(["run", str(write_yaml(tmp_path)), "--out", str(out), *["--dry-run"] * dry_run])
    assert stopped.value.code == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert errors == [
        "lonlib: error: task.search 'sb3-td3' needs Stable-Baselines3, which is not installed: "
        "pip install 'lonlib[sb3]'"
    ]
    assert not out.exists()  # nothing computed or written
    check_search("ddpg")  # lonlib's own search needs no extra


def test_the_sb3_searches_run_on_the_cpu_only(tmp_path):
    config = load_config(write_yaml(tmp_path, "sb3-sac"))
    with pytest.raises(ValueError, match="ddpg.device 'cuda'.*CPU"):
        check_search(config.task.search, "cuda")
    cpu = dataclasses.replace(config, ddpg=dataclasses.replace(config.ddpg, device="cpu"))
    check_search(cpu.task.search, cpu.ddpg.device)


@pytest.mark.parametrize("dry_run", [True, False])
def test_lockstep_with_an_sb3_search_is_refused_by_the_dry_run_as_by_the_run(
    tmp_path, capsys, dry_run
):
    out = tmp_path / "out"
    argv = ["run", str(write_yaml(tmp_path)), "--out", str(out), "--executor", "lockstep"]
    with pytest.raises(SystemExit) as stopped:
        cli_main([*argv, *["--dry-run"] * dry_run])
    assert stopped.value.code == 2
    assert capsys.readouterr().err == (
        "lonlib: error: executor: lockstep batches lonlib's DDPG (task.search: ddpg); "
        "task.search 'sb3-td3' runs with auto, serial, pool or dask\n"
    )
    assert not out.exists()
