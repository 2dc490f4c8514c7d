"""Faults beyond SIGKILL, injected for real: a Dask worker killed mid-run, write failures
(ENOSPC, EROFS, EIO) in each kind of file, a real full and a real read-only file system, a
missing output folder, and two processes on one experiment folder."""

import dataclasses
import errno
import io
import logging
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import psutil
import pytest
import yaml

import lonlib
from lonlib.experiment.running import check_worker_sees_folder, run_experiment, status
from lonlib.storage.atomic import CorruptDataError, DataWriteError, read_json
from lonlib.storage.layout import optimum_path, run_dir, trials_path
from lonlib.storage.lock import LockHeld, exclusive_lock
from lonlib.storage.trials import load_run_state, read_experiment_trials, read_optimum
from tests.conftest import sample_small

COMPARED = ["p", "run", "index", "parent", "fitness", "accepted", "env_steps"]
P = 1e-3
SEARCHES = 3  # local searches per run


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """One p, two runs of three 60-step local searches, uninterrupted: (config, YAML, out)."""
    return sample_small(tmp_path_factory.mktemp("faults"), P, SEARCHES, "faults")


def data_files(out: Path) -> dict[Path, bytes]:
    """Every stored file except temporaries, with its content."""
    return {p: p.read_bytes() for p in out.rglob("*") if p.is_file() and p.suffix != ".tmp"}


def temporaries(out: Path) -> list[Path]:
    return sorted(out.rglob(".*.tmp"))


def assert_same_results(out: Path, expected: Path) -> None:
    """Same trials, bit-identical optima, and no temporary file left."""
    trials = read_experiment_trials(out)
    pd.testing.assert_frame_equal(trials[COMPARED], read_experiment_trials(expected)[COMPARED])
    for row in trials[trials["accepted"]].itertuples():
        ours = read_optimum(optimum_path(out, row.p, row.run, row.index))
        theirs = read_optimum(optimum_path(expected, row.p, row.run, row.index))
        assert np.array_equal(ours.theta, theirs.theta)
        assert np.array_equal(ours.omega, theirs.omega)
    assert temporaries(out) == []


def assert_progress_counts_each_run_once(stderr: str, total: int) -> None:
    """Every frame tqdm drew shows ``n/total`` with n <= total (tqdm drops the ``/total``
    once n exceeds it), and the last shows ``total/total``."""
    frames = [frame for frame in stderr.split("\r") if frame.strip()]
    counts = [re.search(r"\| (\d+)/(\d+) \[", frame) for frame in frames]
    assert frames and all(counts), frames
    assert all(int(c[1]) <= int(c[2]) == total for c in counts), frames
    assert counts[-1][1] == str(total), frames


# ------------------------------------------------------------------ write faults
class WriteFault:
    """Fail the ``nth`` write of one kind of file at one step of the write, the way the OS
    does (an OSError from the system call), by wrapping the ``os`` functions lonlib's
    atomic write uses. At the fault it snapshots every stored file."""

    def __init__(self, monkeypatch, out, target, step, code, nth, keep_temporary=False):
        self.out, self.target, self.step, self.code, self.nth = out, target, step, code, nth
        self.keep_temporary = keep_temporary
        self.seen: list[str] = []
        self.temporary = self.path = self.snapshot = None
        real = {name: getattr(os, name) for name in ("open", "write", "fsync", "replace")}
        real_unlink = os.unlink

        def by_name(name):
            def wrapped(path, *args, **kwargs):
                self._maybe_fail(name, os.fspath(path), lambda: None)
                return real[name](path, *args, **kwargs)

            return wrapped

        def by_handle(name):
            def wrapped(handle, *args, **kwargs):
                path = os.readlink(f"/proc/self/fd/{handle}")
                data = args[0] if args else None

                def partial_write():  # a full disk takes part of the data, then refuses
                    real["write"](handle, bytes(data)[: len(data) // 2])

                self._maybe_fail(name, path, partial_write if name == "write" else lambda: None)
                return real[name](handle, *args, **kwargs)

            return wrapped

        def unlink(path, *args, **kwargs):
            if self.keep_temporary and os.fspath(path) == self.temporary:
                raise OSError(errno.EROFS, os.strerror(errno.EROFS))  # the folder went read-only
            return real_unlink(path, *args, **kwargs)

        monkeypatch.setattr(os, "open", by_name("open"))
        monkeypatch.setattr(os, "replace", by_name("replace"))
        monkeypatch.setattr(os, "write", by_handle("write"))
        monkeypatch.setattr(os, "fsync", by_handle("fsync"))
        monkeypatch.setattr(os, "unlink", unlink)
        self.monkeypatch = monkeypatch

    def _maybe_fail(self, step, path, before) -> None:
        name = Path(path).name
        if step != self.step or not (name.startswith(f".{self.target}") and name.endswith(".tmp")):
            return
        if path not in self.seen:
            self.seen.append(path)
        if len(self.seen) != self.nth or self.temporary is not None:
            return
        before()
        self.temporary = path
        self.path = Path(path).parent / name[1:].rsplit(".", 2)[0]
        self.snapshot = data_files(self.out)
        raise OSError(self.code, os.strerror(self.code))

    def remove(self) -> None:
        self.monkeypatch.undo()


FAULTS = [
    # file kind, failing step, errno, which write of that kind fails, temporary stays
    ("optimum_", "write", errno.ENOSPC, 2, False),
    ("history_", "open", errno.EROFS, 2, False),
    ("trials.parquet", "replace", errno.EROFS, 2, True),
    ("trials.parquet", "fsync", errno.EIO, 1, False),
    ("manifest.json", "write", errno.ENOSPC, 1, False),
]


@pytest.mark.parametrize(("target", "step", "code", "nth", "keep"), FAULTS)
def test_a_failed_write_stops_the_run_damages_nothing_and_resumes(
    reference, tmp_path, monkeypatch, target, step, code, nth, keep
):
    config, _, expected = reference
    out = tmp_path / "out"
    if target == "manifest.json":  # a manifest is rewritten when a session adds runs
        run_experiment(dataclasses.replace(config, runs=1), out, progress=False)
    fault = WriteFault(monkeypatch, out, target, step, code, nth, keep)
    with pytest.raises(DataWriteError) as failed:
        run_experiment(config, out, progress=False)
    fault.remove()
    assert failed.value.errno == code
    assert str(fault.path) in str(failed.value) and os.strerror(code) in str(failed.value)
    assert data_files(out) == fault.snapshot  # nothing stored before changed, nothing added
    assert temporaries(out) == ([Path(fault.temporary)] if keep else [])
    stored = read_json(out / "manifest.json")["config"]["runs"]
    assert stored == (1 if target == "manifest.json" else 2)
    for run in range(2):  # every stored run still reads back
        if trials_path(out, P, run).exists():
            load_run_state(out, P, run, config.basin_hopping(P))
    if target == "manifest.json":
        assert not run_dir(out, P, 1).exists()  # stopped before any compute
    stored = read_experiment_trials(out)  # committed trials only: a temporary is not data
    truth = read_experiment_trials(expected)
    assert len(stored) < len(truth)
    for run, trials in stored.groupby("run"):
        prefix = truth[truth["run"] == run].head(len(trials))
        pd.testing.assert_frame_equal(trials[COMPARED], prefix[COMPARED])
    status(out)
    run_experiment(config, out, progress=False)
    assert_same_results(out, expected)


# ------------------------------------------------------------------ output location
def test_missing_or_unusable_output_folder_is_refused_before_any_compute(
    reference, tmp_path, monkeypatch
):
    config, _, _ = reference

    def no_compute(*args, **kwargs):
        raise AssertionError("compute started")

    monkeypatch.setattr("lonlib.experiment.running.ddpg_local_search", no_compute)
    missing = tmp_path / "not-mounted" / "exp"
    with pytest.raises(DataWriteError, match="not-mounted does not exist") as refused:
        run_experiment(config, missing, progress=False)
    assert refused.value.errno == errno.ENOENT and not missing.parent.exists()
    a_file = tmp_path / "file"
    a_file.write_text("")
    with pytest.raises(DataWriteError, match="is a file") as refused:
        run_experiment(config, a_file, progress=False)
    assert refused.value.errno == errno.ENOTDIR
    with pytest.raises(DataWriteError, match="does not see the experiment's manifest"):
        check_worker_sees_folder(str(tmp_path))  # a Dask worker without the shared folder
    if os.geteuid() != 0:  # root ignores permission bits; the read-only mount test covers it
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        with pytest.raises(DataWriteError, match="Permission denied"):
            run_experiment(config, locked / "exp", progress=False)


def _can_mount() -> bool:
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        return False
    probe = subprocess.run(
        ["unshare", "--mount", "--propagation", "private", "mount", "-t", "tmpfs", "t", "/mnt"],
        capture_output=True,
    )
    return probe.returncode == 0


MOUNTED_RUN = """
import contextlib, io, json, shutil, subprocess, sys
from pathlib import Path
from lonlib.cli import main

mount_point, host, config = map(Path, sys.argv[1:])

def mount(*options):
    subprocess.run(["mount", *options], check=True)

def run():
    stderr = io.StringIO()
    try:
        with contextlib.redirect_stderr(stderr):
            main(["run", str(config), "--out", str(mount_point / "exp"), "--quiet"])
    except SystemExit as stop:
        return stop.code, stderr.getvalue()
    return 0, stderr.getvalue()

results = {}
mount("-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(mount_point))
results["read_only"] = run()
mount("-o", "remount,rw,size=64k", str(mount_point))  # room for about one local search
results["full"] = run()
shutil.copytree(mount_point / "exp", host / "full")
mount("-o", "remount,size=16m", str(mount_point))  # space freed
results["resumed"] = run()
shutil.copytree(mount_point / "exp", host / "resumed")
print(json.dumps(results))
"""


@pytest.mark.skipif(not _can_mount(), reason="needs root and unshare to mount a tmpfs")
def test_real_read_only_and_full_file_systems(reference, tmp_path):
    """A private tmpfs: mounted read-only (refused before any compute), then so small that
    the disk fills mid-run (ENOSPC from the kernel), then enlarged (the run resumes)."""
    config, config_path, expected = reference
    script = tmp_path / "mounted_run.py"
    script.write_text(MOUNTED_RUN)
    mount_point = tmp_path / "mnt"
    mount_point.mkdir()
    env = {**os.environ, "PYTHONPATH": str(Path(lonlib.__file__).parent.parent)}
    command = ["unshare", "--mount", "--propagation", "private", sys.executable, str(script)]
    done = subprocess.run(
        [*command, str(mount_point), str(tmp_path), str(config_path)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    results = yaml.safe_load(done.stdout.splitlines()[-1])
    code, message = results["read_only"]
    assert code == 2 and "exp: Read-only file system" in message
    code, message = results["full"]
    assert code == 2 and "No space left on device" in message and "/exp/" in message
    full = tmp_path / "full"
    assert temporaries(full) == []
    state = load_run_state(full, P, 0, config.basin_hopping(P))
    assert state is not None and 1 <= len(state.trials) < SEARCHES
    assert results["resumed"][0] == 0
    assert_same_results(tmp_path / "resumed", expected)


# ------------------------------------------------------------------ one writer per run
def _wait_for(condition, seconds: float = 120, what: str = "") -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


def _rows(path: Path) -> int:
    return len(pd.read_parquet(path)) if path.exists() else 0


def test_a_second_process_never_writes_a_run_the_first_holds(reference, tmp_path, caplog, capsys):
    """Process A (the CLI) is frozen mid-run while holding run 0. Process B skips run 0,
    does run 1, then waits, naming A; it never touches run 0 meanwhile. A is SIGKILLed:
    the kernel releases its lock and B continues run 0 from what A stored."""
    config, config_path, expected = reference
    out = tmp_path / "out"
    first = trials_path(out, P, 0)
    command = [sys.executable, "-m", "lonlib", "run", str(config_path), "--out", str(out)]
    a = subprocess.Popen([*command, "--quiet"], start_new_session=True)
    outcome = {}
    try:
        _wait_for(lambda: _rows(first) == 1, what="A's first local search")
        os.kill(a.pid, signal.SIGSTOP)
        lock = run_dir(out, P, 0) / ".lock"
        with pytest.raises(LockHeld, match=f"pid {a.pid} "), exclusive_lock(lock, wait=False):
            pass
        frozen = {p: b for p, b in data_files(out).items() if run_dir(out, P, 0) in p.parents}
        assert _rows(first) == 1

        def b() -> None:
            try:
                outcome["trials"] = run_experiment(config, out, progress=True)
            except Exception as error:  # surfaced by the assertions below
                outcome["error"] = error

        caplog.set_level(logging.WARNING, logger="lonlib.experiment.running")
        thread = threading.Thread(target=b)
        thread.start()
        _wait_for(lambda: "waiting for runs" in caplog.text or not thread.is_alive(), what="B")
        assert f"pid {a.pid} " in caplog.text and thread.is_alive(), outcome
        assert _rows(trials_path(out, P, 1)) == SEARCHES  # B did the run A did not hold
        held = {p: b for p, b in data_files(out).items() if run_dir(out, P, 0) in p.parents}
        assert held == frozen  # B wrote nothing into the run A holds
        os.kill(a.pid, signal.SIGKILL)
        a.wait()
        thread.join(timeout=120)
    finally:
        if a.poll() is None:
            os.kill(a.pid, signal.SIGKILL)
            a.wait()
    assert "error" not in outcome, outcome.get("error")
    assert_same_results(out, expected)
    assert_progress_counts_each_run_once(capsys.readouterr().err, total=2)
    by_a = pd.read_parquet(io.BytesIO(frozen[first]))
    assert pd.read_parquet(first)["seconds"].iloc[0] == by_a["seconds"].iloc[0]  # kept, not redone


# ------------------------------------------------------------------ Dask worker loss
def test_a_killed_dask_worker_is_replaced_and_its_run_resumes(reference, tmp_path, capsys):
    config, _, expected = reference
    out = tmp_path / "dask"
    outcome = {}

    def run() -> None:
        try:
            outcome["trials"] = run_experiment(
                config, out, workers=2, scheduler="dask-local", progress=True
            )
        except Exception as error:  # surfaced by the assertions below
            outcome["error"] = error

    thread = threading.Thread(target=run)
    thread.start()
    killed = {}

    def kill_a_worker_mid_run() -> bool:
        ours = {child.pid for child in psutil.Process().children(recursive=True)}
        for run_index in range(2):
            lock = run_dir(out, P, run_index) / ".lock"
            done = _rows(trials_path(out, P, run_index))
            if not 1 <= done < SEARCHES or not lock.exists():
                continue
            try:
                holder = read_json(lock)["pid"]
            except CorruptDataError:  # being written: look again
                continue
            if holder in ours:
                psutil.Process(holder).kill()
                killed.update(run=run_index, pid=holder, stored=done)
                return True
        return not thread.is_alive()

    _wait_for(kill_a_worker_mid_run, seconds=240, what="a Dask worker in the middle of a run")
    thread.join(timeout=300)
    assert killed, "no worker was caught mid-run"
    assert "error" not in outcome, outcome.get("error")
    assert_same_results(out, expected)
    assert _rows(trials_path(out, P, killed["run"])) == SEARCHES > killed["stored"]
    table = status(out)
    assert list(table["finished"]) == [2] and list(table["started"]) == [0]
    assert_progress_counts_each_run_once(capsys.readouterr().err, total=2)


def test_lockstep_workers_stop_when_their_parent_is_killed_and_the_run_resumes(reference, tmp_path):
    """`lonlib run --executor lockstep --workers 2` is SIGKILLed mid-run: its worker
    processes notice within a few seconds and exit (no orphan keeps a run's lock or the
    CPU), and a second session finishes the experiment."""
    config = reference[0]
    out = tmp_path / "out"
    longer = dataclasses.replace(
        config, ddpg=dataclasses.replace(config.ddpg, max_steps=600, min_steps=600)
    )
    path = tmp_path / "long.yaml"
    path.write_text(yaml.safe_dump(longer.to_dict()))
    command = [sys.executable, "-m", "lonlib", "run", str(path), "--out", str(out)]
    lockstep = ["--executor", "lockstep", "--workers", "2", "--slots", "1", "--quiet"]
    parent = subprocess.Popen([*command, *lockstep], start_new_session=True)
    try:
        _wait_for(lambda: _rows(trials_path(out, P, 0)) >= 1, what="a first local search")
        children = _children(parent.pid)
        assert len(children) >= 2
        # killed mid-run: the parent and its workers are alive, a run is unfinished
        assert parent.poll() is None and all(_alive(c) for c in children)
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait(timeout=30)
        _wait_for(lambda: not any(_alive(c) for c in children), seconds=60, what="orphans")
    finally:
        os.killpg(parent.pid, signal.SIGKILL) if _alive(parent.pid) else None
    for run in (0, 1):  # the locks are free again
        with exclusive_lock(run_dir(out, P, run) / ".lock", wait=False):
            pass
    assert min(_rows(trials_path(out, P, run)) for run in (0, 1)) < SEARCHES
    trials = run_experiment(longer, out, progress=False, executor="lockstep", workers=2)
    assert sorted(trials.groupby("run").size()) == [SEARCHES, SEARCHES]


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return False
    return fields[0] != "Z"
