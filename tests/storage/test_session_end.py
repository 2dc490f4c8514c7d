"""A sampling session records its end and wall time in the manifest: the measured cost of an
experiment sampled across sessions (lonlib.storage.manifest.mark_session_ended)."""

import dataclasses
import json
import logging
import shutil
import threading
import time
import warnings

import pytest

from lonlib.cli import main as cli_main
from lonlib.config import load_config
from lonlib.experiment.running import run_experiment
from lonlib.storage import manifest_path, session_seconds
from lonlib.storage.atomic import DataWriteError
from lonlib.storage.layout import MANIFEST_LOCK
from lonlib.storage.lock import exclusive_lock
from lonlib.storage.manifest import mark_session_ended
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
    assert session_seconds(out) == (pytest.approx(first["seconds"] + second["seconds"]), 2, 0)
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
    assert session_seconds(out) == (manifest["sessions"][0]["seconds"], 3, 2)
    before = manifest_path(out).read_bytes()
    assert not mark_session_ended(out, "no such id", 5.0)
    assert manifest_path(out).read_bytes() == before


def test_an_end_that_cannot_be_written_is_logged_not_raised(tiny, monkeypatch, caplog):
    config, out = tiny

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("lonlib.storage.session.mark_session_ended", full_disk)
    with caplog.at_level(logging.WARNING, logger="lonlib.storage.session"):
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
    assert (
        "2 sessions; 1.50 h of sampling time recorded, summed (1 without an end: running," in said
    )


@pytest.mark.parametrize(
    "seconds, counted",
    [
        (0, 0.0),
        (2.5, 2.5),
        (-1, None),
        (True, None),
        (float("inf"), None),
        (float("nan"), None),
        ("7", None),
        (10**400, None),
    ],
)
def test_only_finite_non_negative_seconds_count(seconds, counted):
    manifest = {"config": {}, "sessions": [{"seconds": seconds}, {"seconds": 1.0}]}
    expected = (1.0 + counted, 2, 0) if counted is not None else (1.0, 2, 1)
    assert session_seconds(manifest) == expected


@pytest.mark.parametrize("sessions", [None, 5, "abc", {"a": 1}, [{"seconds": 10**400}]])
def test_status_reports_a_crafted_manifest_without_a_traceback(
    tiny_experiment, tmp_path, sessions, capsys
):
    _, stored, _ = tiny_experiment
    out = tmp_path / "copy"
    shutil.copytree(stored, out)
    manifest = json.loads(manifest_path(out).read_text())
    manifest["sessions"] = sessions
    manifest_path(out).write_text(json.dumps(manifest))
    assert cli_main(["status", str(out)]) in (0, None)
    assert " h of sampling time recorded, summed" in capsys.readouterr().out


def test_an_error_recording_the_end_never_hides_the_sessions_own(tiny, monkeypatch):
    config, out = tiny

    def edits_manifest_then_fails(*args, **kwargs):
        manifest = json.loads(manifest_path(out).read_text())
        manifest["sessions"] = None  # edited into another shape during the session
        manifest_path(out).write_text(json.dumps(manifest))
        raise RuntimeError("the session's own error")

    monkeypatch.setattr("lonlib.experiment.running.execute_runs", edits_manifest_then_fails)
    with pytest.raises(RuntimeError, match="the session's own error"):
        run_experiment(dataclasses.replace(config, executor="serial"), out, progress=False)


def test_a_session_raising_right_after_its_start_records_its_end(tiny, monkeypatch):
    config, out = tiny
    monkeypatch.setattr("lonlib.experiment.running.torch_cpu_capability", lambda: "DEFAULT")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # python -W error: the kernel warning raises
        with pytest.raises(Warning):
            run_experiment(config, out, progress=False)
    (session,) = _sessions(out)
    assert "ended" in session


def test_the_end_waits_for_the_manifest_lock_of_a_session_starting_meanwhile(tiny, monkeypatch):
    """A session starting on the folder holds the manifest lock from reading the manifest to
    writing it back; an end written without the lock would lose one of the two writes."""
    config, out = tiny
    from lonlib.experiment import running

    real = running.execute_runs
    holding = threading.Event()

    def other_session_starts():
        with exclusive_lock(out / MANIFEST_LOCK, record_holder=False):
            manifest = json.loads(manifest_path(out).read_text())
            holding.set()
            time.sleep(1.0)
            manifest["sessions"].append({"started": "other", "id": "other"})
            manifest_path(out).write_text(json.dumps(manifest))

    def then_another_session_starts(*args, **kwargs):
        real(*args, **kwargs)
        threading.Thread(target=other_session_starts, daemon=True).start()
        holding.wait()

    monkeypatch.setattr(running, "execute_runs", then_another_session_starts)
    run_experiment(dataclasses.replace(config, executor="serial"), out, progress=False)
    mine, other = _sessions(out)
    assert "ended" in mine and other["id"] == "other"


def test_a_lock_held_too_long_is_logged_and_the_session_returns(tiny, monkeypatch, caplog):
    config, out = tiny
    from lonlib.experiment import running

    real = running.execute_runs
    monkeypatch.setattr("lonlib.storage.session.SESSION_END_LOCK_SECONDS", 0.5)
    release = threading.Event()
    holding = threading.Event()

    def stuck_holder():
        with exclusive_lock(out / MANIFEST_LOCK, record_holder=False):
            holding.set()
            release.wait(10)

    def then_the_lock_is_stuck(*args, **kwargs):
        real(*args, **kwargs)
        threading.Thread(target=stuck_holder, daemon=True).start()
        holding.wait()

    monkeypatch.setattr(running, "execute_runs", then_the_lock_is_stuck)
    with caplog.at_level(logging.WARNING, logger="lonlib.storage.session"):
        run_experiment(dataclasses.replace(config, executor="serial"), out, progress=False)
    release.set()
    assert "could not record this session's end" in caplog.text
    assert "ended" not in _sessions(out)[0]


def test_recording_the_end_leaves_a_removed_folder_removed(tiny, monkeypatch):
    config, out = tiny

    def folder_removed_then_interrupted(*args, **kwargs):
        shutil.rmtree(out)
        raise KeyboardInterrupt

    monkeypatch.setattr("lonlib.experiment.running.execute_runs", folder_removed_then_interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(dataclasses.replace(config, executor="serial"), out, progress=False)
    assert not out.exists()
