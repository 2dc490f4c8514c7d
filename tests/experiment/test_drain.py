"""Draining a lockstep experiment (``--drain-after``): from the drain time on no local search
starts, those in flight are stored, the call returns, and calling again continues to the
trials of an uninterrupted run, bit for bit."""

from __future__ import annotations

import hashlib
import io
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from tqdm import tqdm

import lonlib.experiment.lockstep
from lonlib.cli import main
from lonlib.config import load_config
from lonlib.experiment.lockstep import run_lockstep
from lonlib.experiment.running import _refresh, pending_runs, run_experiment
from lonlib.experiment.runs import hold_runs
from lonlib.storage.inflight import inflight_checkpoints
from lonlib.storage.status import run_status
from lonlib.storage.trials import read_experiment_trials
from tests.conftest import write_tiny_yaml


def snapshot(folder: Path) -> tuple[pd.DataFrame, dict]:
    """Trials (without timings) and every stored optimum's parameters and history."""
    trials = read_experiment_trials(folder).drop(columns=["seconds"])
    files: dict = {}
    for path in sorted(folder.glob("p=*/run_*/*")):
        key = str(path.relative_to(folder))
        if path.suffix == ".npz":
            with np.load(path) as data:
                files[key] = hashlib.sha256(
                    b"".join(data[k].tobytes() for k in sorted(data.files))
                ).hexdigest()
        elif path.name.startswith("history_"):
            files[key] = pd.read_parquet(path).drop(columns=["seconds"])
    return trials, files


def assert_same(got: tuple[pd.DataFrame, dict], want: tuple[pd.DataFrame, dict]) -> None:
    """Bit for bit: trials (fitness, parameters' files, histories) and the same files."""
    pd.testing.assert_frame_equal(got[0], want[0], check_exact=True)
    assert got[1].keys() == want[1].keys()
    for key, value in got[1].items():
        if isinstance(value, pd.DataFrame):
            pd.testing.assert_frame_equal(value, want[1][key], check_exact=True)
        else:
            assert value == want[1][key], key


@pytest.fixture
def config(tmp_path):
    return load_config(write_tiny_yaml(tmp_path))  # 2 p x 2 runs, up to 4 searches each


def test_a_drain_at_once_stores_the_first_search_of_each_run_in_flight(
    config, tiny_experiment, tmp_path, monkeypatch
):
    written = []
    save = lonlib.experiment.lockstep.save_inflight
    monkeypatch.setattr(
        lonlib.experiment.lockstep,
        "save_inflight",
        lambda *args: written.append(save(*args)),
    )
    out = tmp_path / "out"
    trials = run_experiment(
        config,
        out,
        progress=False,
        executor="lockstep",
        slots=2,
        drain_after_seconds=0,
        checkpoint_seconds=0,  # a checkpoint every step: the drained batch removes its own
    )
    assert written  # the batch was in a checkpoint while it drained
    # the first fill (2 of the 4 runs) trained one search each, then no slot was refilled
    assert list(zip(trials["p"], trials["run"], trials["index"], strict=True)) == [
        (1e-3, 0, 0),
        (1e-3, 1, 0),
    ]
    runs = run_status(out)
    assert runs["state"].tolist() == ["started", "started", "not started", "not started"]
    assert pending_runs(config, out) == [(p, r) for p in config.perturbations for r in (0, 1)]
    assert not inflight_checkpoints(out) and not list((out / ".inflight").iterdir())
    with hold_runs(out, [(1e-3, 0), (1e-3, 1)]) as free:
        assert free  # their locks were released: a later call continues them
    want = tiny_experiment[2]  # an uninterrupted run's first searches, bit for bit
    want = want[want["index"] == 0].set_index(["p", "run"]).loc[[(1e-3, 0), (1e-3, 1)]]
    np.testing.assert_array_equal(trials["fitness"], want["fitness"])


def test_calling_again_continues_to_the_uninterrupted_trials(config, tiny_experiment, tmp_path):
    out = tmp_path / "out"
    drain = {"progress": False, "executor": "lockstep", "drain_after_seconds": 0}
    run_experiment(config, out, slots=2, **drain)
    # the two started runs continue from their stored trial, one run starts: a search each
    trials = run_experiment(config, out, slots=3, **drain)
    assert len(trials) == 5
    assert run_status(out)["local_searches"].tolist() == [2, 2, 1, 0]
    run_experiment(config, out, progress=False, executor="lockstep", slots=2)  # no drain
    assert pending_runs(config, out) == [] and not inflight_checkpoints(out)
    assert_same(snapshot(out), snapshot(tiny_experiment[1]))


def test_each_lockstep_process_drains(config, tmp_path):
    out = tmp_path / "out"
    trials = run_experiment(
        config,
        out,
        progress=False,
        executor="lockstep",
        slots=1,
        workers=2,
        drain_after_seconds=0,
    )
    # each process trained the first search of its first run, and started no other
    assert sorted(zip(trials["p"], trials["run"], strict=True)) == [(1e-3, 0), (1e-3, 1)]
    assert len(pending_runs(config, out)) == 4 and not inflight_checkpoints(out)


def test_the_batch_says_it_drains_and_the_bar_shows_it(config, tiny_experiment, tmp_path):
    ticks, ended = [], []
    jobs = [(p, run) for p in config.perturbations for run in (0, 1)]
    yielded = run_lockstep(
        tmp_path / "out",
        config,
        jobs,
        ended.append,
        slots=2,
        on_tick=ticks.append,
        tick_seconds=0,
        drain_at=time.monotonic(),
    )
    assert not yielded and not ended  # no run ended: one search each
    assert ticks and all(tick.get("draining") for tick in ticks)
    bar = tqdm(total=4, desc="tiny runs", file=io.StringIO())
    for _ in range(2):
        _refresh(bar, tiny_experiment[1], batch={"in_flight": 1, "draining": True})
    assert bar.desc == "tiny runs (draining)" and "draining" not in str(bar.postfix)


def test_the_cli_says_what_is_left_and_the_same_command_continues(
    tiny_experiment, tmp_path, capsys
):
    out = tmp_path / "out"
    argv = ["run", str(write_tiny_yaml(tmp_path)), "--executor", "lockstep", "--slots", "4"]
    argv += ["--drain-after", "0", "--out", str(out), "--quiet"]
    main(argv)
    assert "4 of 4 runs unfinished: run the same command again to continue them" in (
        capsys.readouterr().out
    )
    for _ in range(3):  # a run ends after 4 searches at most: one a call
        main(argv)
        if "all 4 runs finished" in capsys.readouterr().out:
            break
    assert pending_runs(load_config(tmp_path / "tiny.yaml"), out) == []
    assert_same(snapshot(out), snapshot(tiny_experiment[1]))


@pytest.mark.parametrize("executor", ["serial", "pool", "auto"])
def test_only_the_lockstep_executor_drains(config, tmp_path, executor):
    with pytest.raises(ValueError, match=r"needs the lockstep executor; executor '(serial|pool)'"):
        run_experiment(
            config, tmp_path / "out", workers=2, executor=executor, drain_after_seconds=60
        )
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("minutes", ["-1", "nan", "1e9"])
@pytest.mark.parametrize("dry_run", [True, False])
def test_a_drain_time_out_of_range_is_refused_before_any_compute(
    tmp_path, capsys, minutes, dry_run
):
    argv = ["run", str(write_tiny_yaml(tmp_path)), "--executor", "lockstep", "--slots", "2"]
    argv += ["--drain-after", minutes, "--out", str(tmp_path / "out")] + ["--dry-run"] * dry_run
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    error = capsys.readouterr().err
    want = "must be a number" if minutes == "nan" else "must be in [0, 10000000]"
    assert error.startswith(f"lonlib: error: --drain-after {want}"), error
    assert not (tmp_path / "out").exists()
    with pytest.raises(ValueError, match=r"drain_after_seconds must be in \[0, "):
        run_experiment(
            load_config(tmp_path / "tiny.yaml"),
            tmp_path / "out",
            executor="lockstep",
            drain_after_seconds=-1.0,
        )
    assert not (tmp_path / "out").exists()


def test_the_cli_refuses_a_drain_for_another_executor(tmp_path, capsys):
    argv = ["run", str(write_tiny_yaml(tmp_path)), "--executor", "pool", "--workers", "2"]
    with pytest.raises(SystemExit):
        main([*argv, "--drain-after", "5", "--out", str(tmp_path / "out"), "--dry-run"])
    assert "executor 'pool' runs whole runs" in capsys.readouterr().err
    main([*argv, "--executor", "lockstep", "--drain-after", "5", "--out", "x", "--dry-run"])
    assert "draining after 5 minutes" in capsys.readouterr().out
