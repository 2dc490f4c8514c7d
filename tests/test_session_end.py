"""A sampling session records its end and wall time in the manifest: the measured cost of an
experiment sampled across sessions (lonlib.storage.manifest.mark_session_ended)."""

import dataclasses
import json
import logging

import pytest

from lonlib.cli import main as cli_main
from lonlib.experiment.running import load_config, run_experiment
from lonlib.storage import manifest_path, mark_session_ended, session_seconds
from lonlib.storage.store import DataWriteError
from tests.conftest import write_tiny_yaml


@pytest.fixture
def tiny(tmp_path):
    config = load_config(write_tiny_yaml(tmp_path))
    return dataclasses.replace(config, runs=1, perturbations=(1e-3,)), tmp_path / "out"


def _sessions(out):
    return json.loads(manifest_path(out).read_text())["sessions"]


def test_each_sampling_session_records_its_end_and_wall_seconds(tiny):
    config, out = tiny
    run_experiment(config, out, progress=False)
    run_experiment(dataclasses.replace(config, runs=2), out, progress=False)  # adds a run
    first, second = _sessions(out)
    assert first["id"] != second["id"]
    for session in (first, second):
        assert session["ended"] >= session["started"] and session["seconds"] > 0
    assert session_seconds(out) == (pytest.approx(first["seconds"] + second["seconds"]), 0)
    before = manifest_path(out).read_bytes()
    run_experiment(dataclasses.replace(config, runs=2), out, progress=False)
    assert manifest_path(out).read_bytes() == before  # a finished experiment stays untouched


def test_a_session_that_raises_records_its_end_and_keeps_its_error(tiny, monkeypatch):
    config, out = tiny

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("lonlib.experiment.running.execute_runs", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(dataclasses.replace(config, executor="serial"), out, progress=False)
    (session,) = _sessions(out)
    assert session["seconds"] >= 0 and "ended" in session


def test_sessions_without_an_end_are_counted_and_an_unknown_id_writes_nothing(tiny):
    config, out = tiny
    run_experiment(config, out, progress=False)
    manifest = json.loads(manifest_path(out).read_text())
    killed = {k: v for k, v in manifest["sessions"][0].items() if k not in ("ended", "seconds")}
    manifest["sessions"] = [manifest["sessions"][0], killed, {"started": "old code, no id"}]
    manifest_path(out).write_text(json.dumps(manifest))
    assert session_seconds(out) == (manifest["sessions"][0]["seconds"], 2)
    before = manifest_path(out).read_bytes()
    assert not mark_session_ended(out, "no such id", 5.0)
    assert manifest_path(out).read_bytes() == before


def test_an_end_that_cannot_be_written_is_logged_not_raised(tiny, monkeypatch, caplog):
    config, out = tiny

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("lonlib.experiment.running.mark_session_ended", full_disk)
    with caplog.at_level(logging.WARNING, logger="lonlib.experiment.running"):
        trials = run_experiment(config, out, progress=False)
    assert len(trials) > 0
    assert "could not record this session's end" in caplog.text
    assert "ended" not in _sessions(out)[0]


def test_a_session_stopped_by_a_failed_write_writes_nothing_more(tiny, monkeypatch):
    config, out = tiny
    run_experiment(config, out, progress=False)
    before = manifest_path(out).read_bytes()

    def failed_write(*args, **kwargs):
        raise DataWriteError(28, "No space left on device", str(out / "trials.parquet"))

    monkeypatch.setattr("lonlib.experiment.running.execute_runs", failed_write)
    with pytest.raises(DataWriteError):
        run_experiment(dataclasses.replace(config, runs=2, executor="serial"), out, progress=False)
    (first, second) = _sessions(out)
    assert "ended" in first and "ended" not in second  # the second's start was written
    assert manifest_path(out).read_bytes() != before


def test_status_says_the_sessions_and_their_recorded_wall_time(tiny, capsys):
    config, out = tiny
    run_experiment(config, out, progress=False)
    manifest = json.loads(manifest_path(out).read_text())
    manifest["sessions"][0]["seconds"] = 5400.0
    manifest["sessions"].append({"started": "killed"})
    manifest_path(out).write_text(json.dumps(manifest))
    assert cli_main(["status", str(out)]) in (0, None)
    said = capsys.readouterr().out
    assert "2 sessions; 1.50 h of sampling wall time recorded (1 recorded no end" in said
