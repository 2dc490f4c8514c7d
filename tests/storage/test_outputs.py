"""Outputs put in place (:mod:`lonlib.storage.outputs`): ``lonlib analyse`` and ``lonlib record``
write each file under a temporary name, seal their digests ahead, then rename them into place
and reseal, so that a kill at any point leaves a folder that ``lonlib verify`` does not
report as tampered (at most pending), and the same command again completes it."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from fnmatch import fnmatch
from pathlib import Path

import pytest

import lonlib.storage.outputs as outputs
from lonlib.analysis.pipeline import analyse, load_experiment, record_optima
from lonlib.analysis.verify import verify_experiment
from lonlib.cli import main as cli_main
from lonlib.storage.digests import SEAL_NAME, check_experiment_seal
from lonlib.storage.layout import read_manifest
from lonlib.storage.outputs import OUTPUTS_LOCK, STAGING, publish_figures, staging_folder
from tests.conftest import sample_small

ROOT = Path(__file__).resolve().parents[2]
P = 1e-3
EARLIER = {"bins": 20, "seed": 1, "conditioning": False}
"""An earlier analysis: other bins and layout (other figures), without the conditioning (the
analysis under test adds its files)."""
RECORDINGS = 2

# Where a kill strikes: "call:<f>" on entering lonlib.storage.outputs' <f>, else
# "<file name pattern>#<n>" after the n-th rename onto a matching name (os.replace: the
# outputs' renames and every atomic write, the seal's included).
FIGURE_POINTS = [
    "call:seal_outputs_ahead",  # every output written under a temporary name, nothing sealed
    "seal.json#1",  # sealed ahead, nothing renamed
    "fig2_optima_boxplot.png#1",  # the first figure renamed, the others not
    "summary.csv#1",  # part-way
    "call:reseal_outputs",  # every figure renamed, the reseal not written
    "seal.json#2",  # resealed, the temporary folder not yet removed
]
RECORDING_POINTS = [
    "call:seal_outputs_ahead",
    "seal.json#1",
    "*.rrd#1",
    "call:reseal_outputs",
    "seal.json#2",
]


class Killed(BaseException):
    """A kill simulated in the process: nothing in lonlib catches it."""


def kill_at(monkeypatch, point: str, kill=None) -> None:
    """Make ``point`` (see :data:`FIGURE_POINTS`) raise :class:`Killed` (or call ``kill``)."""

    def die(*args, **kwargs):
        if kill is not None:
            kill()
        raise Killed(point)

    if point.startswith("call:"):
        monkeypatch.setattr(outputs, point.removeprefix("call:"), die)
        return
    pattern, count = point.split("#")
    original, seen = os.replace, [0]

    def replace_then_maybe_die(src, dst, *args, **kwargs):
        original(src, dst, *args, **kwargs)
        if fnmatch(Path(dst).name, pattern):
            seen[0] += 1
            if seen[0] == int(count):
                die()

    monkeypatch.setattr(os, "replace", replace_then_maybe_die)


@pytest.fixture(scope="module")
def sampled(tmp_path_factory):
    """One p, two runs of two 60-step searches, sealed: the output folder."""
    return sample_small(tmp_path_factory.mktemp("outputs"), P, 2, "outputs")[2]


@pytest.fixture(scope="module")
def expected(sampled, tmp_path_factory):
    """``sampled`` analysed without interruption (after :data:`EARLIER`): its sealed
    figures."""
    out = tmp_path_factory.mktemp("expected") / "out"
    shutil.copytree(sampled, out)
    analyse(out, close_figures=True, **EARLIER)
    analyse(out, close_figures=True)
    return json.loads((out / SEAL_NAME).read_text())["figures"]["files"]


def copy_of(sampled: Path, tmp_path: Path) -> Path:
    shutil.copytree(sampled, tmp_path / "out")
    return tmp_path / "out"


def assert_not_tampered(out: Path) -> list[tuple[str, str]]:
    """The folder reads as pending at most: its seal check and ``lonlib verify`` find no
    error, its readers read it. Returns what is pending."""
    check = check_experiment_seal(out, read_manifest(out))
    assert check.sealed and check.ok, check.problems
    assert verify_experiment(out).errors == []
    load_experiment(out)  # a reader's gate
    return check.pending


def assert_complete(out: Path) -> None:
    check = check_experiment_seal(out, read_manifest(out))
    assert check.ok and check.pending == [], (check.problems, check.pending)
    seal = json.loads((out / SEAL_NAME).read_text())
    assert "next" not in seal.get("figures", {}) and "recordings_next" not in seal
    assert not list(out.glob(f"*/{STAGING}"))


@pytest.mark.parametrize("earlier", [False, True], ids=["first", "again"])
@pytest.mark.parametrize("point", FIGURE_POINTS)
def test_an_analysis_killed_at_each_point_is_not_tampered_and_completes(
    sampled, expected, tmp_path, monkeypatch, point, earlier
):
    out = copy_of(sampled, tmp_path)
    if earlier:
        analyse(out, close_figures=True, **EARLIER)
    kill_at(monkeypatch, point)
    with pytest.raises(Killed):
        analyse(out, close_figures=True)
    monkeypatch.undo()
    pending = assert_not_tampered(out)
    ahead = [what for name, what in pending if name == SEAL_NAME]
    assert bool(ahead) == (point not in ("call:seal_outputs_ahead", "seal.json#2")), pending
    analyse(out, close_figures=True)
    assert_complete(out)
    files = json.loads((out / SEAL_NAME).read_text())["figures"]["files"]
    assert files == expected  # what an analysis that was not killed seals


def test_a_smaller_analysis_after_a_killed_one_seals_what_the_killed_one_put_in_place(
    sampled, tmp_path, monkeypatch
):
    """Killed after its renames, an analysis with the conditioning left files sealed ahead
    only; the next analysis, without the conditioning, does not write them again and seals
    them as sealed ahead (with the trials they were drawn from), not as files no seal lists."""
    out = copy_of(sampled, tmp_path)
    kill_at(monkeypatch, "call:reseal_outputs")
    with pytest.raises(Killed):
        analyse(out, close_figures=True)
    monkeypatch.undo()
    written = analyse(out, close_figures=True, conditioning=False).files
    assert out / "figures" / "replayed.csv" not in written
    assert_complete(out)
    figures = json.loads((out / SEAL_NAME).read_text())["figures"]
    assert "figures/replayed.csv" in figures["files"] and "inputs_of" not in figures


@pytest.mark.parametrize("earlier", [False, True], ids=["first", "again"])
@pytest.mark.parametrize("point", RECORDING_POINTS)
def test_a_record_killed_at_each_point_is_not_tampered_and_completes(
    sampled, tmp_path, monkeypatch, point, earlier
):
    """A first recording of the folder (no recordings index in its seal) and a second one
    (every recording rewritten, with other bytes)."""
    out = copy_of(sampled, tmp_path)
    if earlier:
        assert len(record_optima(out, limit=RECORDINGS)) == RECORDINGS
    before = {p.name: p.read_bytes() for p in (out / "recordings").glob("*.rrd")}
    kill_at(monkeypatch, point)
    with pytest.raises(Killed):
        record_optima(out, limit=RECORDINGS)
    monkeypatch.undo()
    pending = assert_not_tampered(out)
    ahead = [what for name, what in pending if name == SEAL_NAME]
    assert bool(ahead) == (point not in ("call:seal_outputs_ahead", "seal.json#2")), pending
    if point == "call:seal_outputs_ahead":  # nothing put in place yet
        assert {p.name: p.read_bytes() for p in (out / "recordings").glob("*.rrd")} == before
    paths = record_optima(out, limit=RECORDINGS)
    assert_complete(out)
    index = json.loads((out / SEAL_NAME).read_text())["recordings"]
    assert sorted(index) == sorted(p.name for p in paths)
    assert verify_experiment(out).recordings == RECORDINGS


KILLER = """
import os, signal, sys
from pathlib import Path

import pytest

from lonlib.analysis.pipeline import analyse, record_optima
from tests.storage.test_outputs import RECORDINGS, kill_at

command, out, point = sys.argv[1], Path(sys.argv[2]), sys.argv[3]
with pytest.MonkeyPatch.context() as monkeypatch:
    kill_at(monkeypatch, point, kill=lambda: os.kill(os.getpid(), signal.SIGKILL))
    if command == "analyse":
        analyse(out, close_figures=True)
    else:
        record_optima(out, limit=RECORDINGS)
"""


@pytest.mark.parametrize(
    "command, point", [("analyse", "fig2_optima_boxplot.png#1"), ("record", "*.rrd#1")]
)
def test_a_sigkill_part_way_verifies_and_the_same_command_completes(
    sampled, tmp_path, command, point, capsys
):
    out = copy_of(sampled, tmp_path)
    analyse(out, close_figures=True, **EARLIER)
    record_optima(out, limit=RECORDINGS)
    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, str(script), command, str(out), point],
        env=env,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == -signal.SIGKILL, done.stderr[-2000:]
    cli_main(["verify", str(out)])  # exit status 0: no error
    assert "verify: OK" in capsys.readouterr().out
    cli_main([command, str(out)] + (["--limit", str(RECORDINGS)] if command == "record" else []))
    assert_complete(out)


@pytest.mark.parametrize("point", ["seal.json#1", "call:reseal_outputs"])
def test_a_figure_removed_sealed_ahead_is_not_missing(sampled, tmp_path, monkeypatch, point):
    """A file an analysis no longer makes (the robust claims, when the re-scoring is refused)
    is removed after its removal is sealed ahead: gone before the reseal, it is not a
    missing figure."""
    out = copy_of(sampled, tmp_path)
    analyse(out, close_figures=True)
    assert (out / "figures" / "claims_robust.csv").is_file()
    kill_at(monkeypatch, point)
    with pytest.raises(Killed), staging_folder(out / "figures") as staging:
        (staging / "metrics.csv").write_text("p\n0.001\n")
        publish_figures(out, [staging / "metrics.csv"], removed=["claims_robust.csv"])
    monkeypatch.undo()
    assert_not_tampered(out)
    assert (out / "figures" / "claims_robust.csv").exists() == (point == "seal.json#1")
    with staging_folder(out / "figures") as staging:
        (staging / "metrics.csv").write_text("p\n0.001\n")
        publish_figures(out, [staging / "metrics.csv"], removed=["claims_robust.csv"])
    assert not (out / "figures" / "claims_robust.csv").exists()
    assert_complete(out)


def test_an_unsealed_folder_gets_its_outputs_renamed_and_no_seal(sampled, tmp_path):
    out = copy_of(sampled, tmp_path)
    (out / SEAL_NAME).unlink()
    for path in out.glob("p=*/run_*/digests.json"):
        path.unlink()
    manifest = json.loads((out / "manifest.json").read_text())
    manifest.pop("sealed", None)
    (out / "manifest.json").write_text(json.dumps(manifest))
    with pytest.warns(UserWarning, match="unsealed"):
        result = analyse(out, close_figures=True, conditioning=False)
    assert all(path.parent == out / "figures" and path.is_file() for path in result.files)
    assert not (out / SEAL_NAME).exists() and not (out / "figures" / STAGING).exists()


def killed_the_second_time(sampled: Path, tmp_path: Path, monkeypatch, point: str, first, again):
    """A copy of ``sampled`` given ``first``, then ``again`` killed at ``point``."""
    out = copy_of(sampled, tmp_path)
    first(out)
    kill_at(monkeypatch, point)
    with pytest.raises(Killed):
        again(out)
    monkeypatch.undo()
    return out


def analysis_killed_at(sampled: Path, tmp_path: Path, monkeypatch, point: str) -> Path:
    """A copy of ``sampled`` analysed once (:data:`EARLIER`), then analysed again and killed
    at ``point``."""
    return killed_the_second_time(
        sampled,
        tmp_path,
        monkeypatch,
        point,
        lambda out: analyse(out, close_figures=True, **EARLIER),
        lambda out: analyse(out, close_figures=True),
    )


def record_killed_at(sampled: Path, tmp_path: Path, monkeypatch, point: str) -> Path:
    """A copy of ``sampled`` recorded once, then recorded again and killed at ``point``."""

    def record(out: Path) -> None:
        record_optima(out, limit=RECORDINGS)

    return killed_the_second_time(sampled, tmp_path, monkeypatch, point, record, record)


def test_verify_seal_refuses_a_folder_an_analysis_left_part_way(sampled, tmp_path, monkeypatch):
    """A mixed set of old and new figures is never sealed as complete: ``--seal`` asks for
    the interrupted command first."""
    out = analysis_killed_at(sampled, tmp_path, monkeypatch, "summary.csv#1")
    with pytest.raises(SystemExit) as exited:
        cli_main(["verify", str(out), "--seal"])
    assert exited.value.code == 2
    assert json.loads((out / SEAL_NAME).read_text())["figures"].get("next")
    analyse(out, close_figures=True)
    assert_complete(out)


def test_a_figure_tampered_while_its_new_digest_is_pending_ahead_differs(
    sampled, tmp_path, monkeypatch
):
    """A figure put in place as sealed ahead (an analysis killed part-way) is accepted only
    while it holds what was sealed ahead: edited, verify names it."""
    out = analysis_killed_at(sampled, tmp_path, monkeypatch, "fig2_optima_boxplot.png#1")
    name = "figures/fig2_optima_boxplot.png"
    assert name in json.loads((out / SEAL_NAME).read_text())["figures"]["next"]["files"]
    (out / name).write_bytes((out / name).read_bytes() + b"\0")
    problems = dict(check_experiment_seal(out, read_manifest(out)).problems)
    assert "differs from its seal" in problems[name], problems
    assert any(name in str(error) for error in verify_experiment(out).errors)


def test_a_recording_tampered_while_its_new_digest_is_pending_ahead_differs(
    sampled, tmp_path, monkeypatch
):
    """The same for a recording sealed ahead (``recordings_next``): the one put in place and
    the one not yet, each edited, are named."""
    out = record_killed_at(sampled, tmp_path, monkeypatch, "*.rrd#1")
    names = sorted(json.loads((out / SEAL_NAME).read_text())["recordings_next"])
    assert len(names) == RECORDINGS
    for name in names:
        path = out / "recordings" / name
        path.write_bytes(path.read_bytes() + b"\0")
    problems = dict(check_experiment_seal(out, read_manifest(out)).problems)
    for name in names:
        assert "differs from its seal" in problems[f"recordings/{name}"], problems
    assert len(verify_experiment(out).errors) >= RECORDINGS


def test_a_smaller_record_keeps_the_earlier_recordings_in_the_index(sampled, tmp_path, capsys):
    """``record --limit 1`` after ``--limit 2``: the recording it does not write again stays
    in the index, and the folder verifies."""
    out = copy_of(sampled, tmp_path)
    cli_main(["record", str(out), "--limit", "2"])
    cli_main(["record", str(out), "--limit", "1"])
    index = json.loads((out / SEAL_NAME).read_text())["recordings"]
    assert sorted(index) == sorted(p.name for p in (out / "recordings").glob("*.rrd"))
    assert len(index) == 2
    capsys.readouterr()
    cli_main(["verify", str(out)])
    assert "verify: OK" in capsys.readouterr().out
    assert_complete(out)


@pytest.mark.parametrize("later", ["analyse", "thin"])
def test_a_later_reseal_keeps_the_recordings_a_killed_record_sealed_ahead(
    sampled, tmp_path, monkeypatch, later
):
    """A record killed after its seal ahead, then an analyse (or a thin) that reseals the root:
    the recordings sealed ahead stay sealed ahead (pending, never a false tamper), and record
    again completes them."""
    import lonlib.storage.thin as thin

    out = record_killed_at(sampled, tmp_path, monkeypatch, "*.rrd#1")
    if later == "analyse":
        analyse(out, close_figures=True, conditioning=False)
    else:  # a thin that rewrites every history (these tiny ones have no row to drop)
        monkeypatch.setattr(thin, "thinned_history", lambda history: history.iloc[:0])
        assert thin.thin_histories(out).thinned > 0  # then it reseals the root
        monkeypatch.undo()
    assert "recordings_next" in json.loads((out / SEAL_NAME).read_text())
    pending = assert_not_tampered(out)
    assert any("recordings sealed ahead" in what for _, what in pending), pending
    record_optima(out, limit=RECORDINGS)
    assert_complete(out)


HOLDER = """
import sys, time
from pathlib import Path

from lonlib.storage.outputs import staging_folder

folder, marks = Path(sys.argv[1]), Path(sys.argv[2])
with staging_folder(folder):
    (marks / "held").touch()
    deadline = time.monotonic() + 120
    while not (marks / "release").exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    (marks / "left").touch()
"""


def wait_for(path: Path, process: subprocess.Popen) -> None:
    """Until ``path`` exists (the process, alive, wrote it): fails if the process ends first."""
    deadline = time.monotonic() + 120
    while not path.exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.01)


def test_two_processes_staging_one_folder_take_turns(tmp_path):
    """The outputs' lock: while one process is in its staging block, the lock is held; a
    second process staging the same folder enters only once the first has left."""
    from lonlib.storage.lock import LockHeld, exclusive_lock

    folder, marks = tmp_path / "figures", tmp_path / "marks"
    marks.mkdir()
    script = tmp_path / "holder.py"
    script.write_text(HOLDER)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    first = subprocess.Popen(
        [sys.executable, str(script), str(folder), str(marks)],
        env=env,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_for(marks / "held", first)
        with pytest.raises(LockHeld), exclusive_lock(folder / OUTPUTS_LOCK, wait=False):
            pass
        (marks / "release").touch()
        with staging_folder(folder) as staging:  # waits for the first to leave its block
            assert (marks / "left").exists()
            assert staging.is_dir()
    finally:
        first.communicate(timeout=120)
    assert first.returncode == 0


def test_the_robust_claims_an_analysis_no_longer_makes_are_removed(sampled, tmp_path, monkeypatch):
    """An analysis whose re-scoring is refused (no robust claims) removes the earlier ones,
    and the folder verifies."""
    import pandas as pd

    import lonlib.analysis.pipeline as pipeline
    from lonlib.analysis.claims_rescored import FILES

    out = copy_of(sampled, tmp_path)
    analyse(out, close_figures=True)
    assert all((out / "figures" / name).is_file() for name in FILES)
    refused = (pd.DataFrame(), pd.DataFrame(), [])
    monkeypatch.setattr(pipeline, "write_robust_claims", lambda *args, **kwargs: refused)
    analyse(out, close_figures=True)
    assert not any((out / "figures" / name).exists() for name in FILES)
    sealed = json.loads((out / SEAL_NAME).read_text())["figures"]["files"]
    assert not any(f"figures/{name}" in sealed for name in FILES)
    assert_complete(out)
    assert verify_experiment(out).errors == []


def test_a_check_that_read_the_seal_before_an_analysis_renamed_reads_it_again(
    sampled, tmp_path, monkeypatch
):
    """A seal check that read ``seal.json`` before ``analyse`` sealed ahead, and the files
    after it renamed them, finds differences among the figures only: it reads the seal and
    the files again, once, before reporting them (a real difference stays reported)."""
    import lonlib.storage._digests_check as digests_check

    out = copy_of(sampled, tmp_path)
    analyse(out, close_figures=True, **EARLIER)
    old = json.loads((out / SEAL_NAME).read_text())
    analyse(out, close_figures=True)
    real, reads = digests_check.read_seal, []

    def first_read_is_old(path):
        reads.append(path)
        return old if len(reads) == 1 else real(path)

    monkeypatch.setattr(digests_check, "read_seal", first_read_is_old)
    check = check_experiment_seal(out, read_manifest(out))
    assert check.ok and check.pending == [], (check.problems, check.pending)
    assert len(reads) == 2
    path = out / "figures" / "summary.csv"
    path.write_text(path.read_text() + "\n")
    reads.clear()
    problems = dict(check_experiment_seal(out, read_manifest(out)).problems)
    assert list(problems) == ["figures/summary.csv"] and len(reads) == 2


@pytest.mark.parametrize("planted", ["file", "link to a folder", "dangling link"])
def test_a_file_or_link_planted_under_the_staging_name_is_removed(tmp_path, planted):
    """``.staging.tmp`` is lonlib's reserved name: a file or link there is unlinked (a link
    never followed), not a misleading write error."""
    folder, elsewhere = tmp_path / "figures", tmp_path / "elsewhere"
    folder.mkdir()
    elsewhere.mkdir()
    (elsewhere / "kept.txt").write_text("kept")
    staging = folder / STAGING
    if planted == "file":
        staging.write_text("not a folder")
    elif planted == "link to a folder":
        staging.symlink_to(elsewhere)
    else:
        staging.symlink_to(tmp_path / "nowhere")
    with staging_folder(folder) as made:
        assert made == staging and made.is_dir() and not made.is_symlink()
        assert list(made.iterdir()) == []
    assert (elsewhere / "kept.txt").read_text() == "kept"


def test_a_planted_staging_name_that_cannot_be_removed_is_named(tmp_path, monkeypatch):
    from lonlib.storage.atomic import DataWriteError

    folder = tmp_path / "figures"
    folder.mkdir()
    (folder / STAGING).write_text("not a folder")
    real_unlink = Path.unlink

    def refuse(self, *args, **kwargs):
        if self.name == STAGING:
            raise PermissionError(13, "Permission denied")
        return real_unlink(self, *args, **kwargs)

    monkeypatch.setattr(Path, "unlink", refuse)
    reserved = r"\.staging\.tmp.*reserved"
    with pytest.raises(DataWriteError, match=reserved) as raised, staging_folder(folder):
        pass
    assert str(folder / STAGING) in str(raised.value) and "\n" not in str(raised.value)


def test_a_killed_seal_writes_temporary_is_removed_by_the_next_seal_ahead(sampled, tmp_path):
    """``.seal.json.<random>.tmp``, what a seal write killed before its rename leaves, is
    removed when the outputs are sealed ahead (under the manifest lock)."""
    out = copy_of(sampled, tmp_path)
    leftover = out / ".seal.json.k1ll3d.tmp"
    leftover.write_text('{"format": 1')
    with staging_folder(out / "figures") as staging:
        (staging / "metrics.csv").write_text("p\n0.001\n")
        publish_figures(out, [staging / "metrics.csv"])
    assert not leftover.exists()
    assert_complete(out)


def test_figures_removed_with_nothing_staged_are_removed_and_resealed(sampled, tmp_path):
    """An analysis that writes nothing but must remove stale files: their removal is sealed
    ahead (as None) and resealed."""
    out = copy_of(sampled, tmp_path)
    analyse(out, close_figures=True)
    gone = ["claims_robust.csv", "claims_nominal_robust.md"]
    with staging_folder(out / "figures") as staging:
        assert publish_figures(out, [], removed=gone, staging=staging) == []
    assert not any((out / "figures" / name).exists() for name in gone)
    sealed = json.loads((out / SEAL_NAME).read_text())["figures"]["files"]
    assert not any(f"figures/{name}" in sealed for name in gone)
    assert "figures/summary.csv" in sealed
    assert_complete(out)


def test_figures_are_sealed_ahead_as_drawn_from_the_trials_the_analysis_loaded(
    sampled, tmp_path, monkeypatch
):
    """A session appends a trial to each run after the analysis loaded the trials, and the
    analysis is killed between sealing its figures ahead and renaming them into place: they
    are sealed ahead as drawn from the trials it loaded, not from those sealed now."""
    import dataclasses

    from lonlib.analysis.landscape import StoredExperiment
    from lonlib.config import load_config
    from lonlib.experiment.running import run_experiment
    from lonlib.storage._digests_format import inputs_now

    out = copy_of(sampled, tmp_path)
    experiment = StoredExperiment.load(out)
    loaded = inputs_now(out, json.loads((out / SEAL_NAME).read_text()))
    config = load_config(sampled.parent / "outputs.yaml")
    config = dataclasses.replace(config, max_local_searches=3)
    run_experiment(config, out, progress=False, allow_changes=["max_local_searches"])
    assert loaded != inputs_now(out, json.loads((out / SEAL_NAME).read_text()))
    kill_at(monkeypatch, "call:_rename")
    with pytest.raises(Killed):
        analyse(experiment, close_figures=True, conditioning=False)
    ahead = json.loads((out / SEAL_NAME).read_text())["figures"]["next"]
    assert ahead["files"] and ahead["inputs"] == loaded
