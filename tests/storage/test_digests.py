"""Digests (:mod:`lonlib.storage.digests`): every change to a stored experiment is named by
``lonlib verify`` and refused by its readers; an interrupted write never reads as tampered;
the committed folders are sealed and match their seals."""

import io
import json
import os
import shutil
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lonlib.analysis.pipeline import load_experiment
from lonlib.analysis.verify import verify_experiment
from lonlib.cli import main as cli_main
from lonlib.config import load_config
from lonlib.experiment.running import run_experiment
from lonlib.storage.digests import (
    RUN_DIGESTS,
    SEAL_NAME,
    SEALED_FIELD,
    TamperedDataError,
    TamperedDataWarning,
    UnsealedDataWarning,
    check_experiment_seal,
    check_files_seal,
    seal_files,
)
from lonlib.storage.layout import optimum_path, read_manifest, run_dir, trials_path
from lonlib.storage.thin import thin_histories
from lonlib.storage.trials import load_run_state
from tests.conftest import reseal, sample_small

ROOT = Path(__file__).resolve().parents[2]
COMMITTED = [ROOT / "data" / "reference", ROOT / "data" / "one-cart"]
P, SEARCHES = 1e-3, 3


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """One p, two runs of three 60-step searches, uninterrupted: (YAML path, folder)."""
    _, path, out = sample_small(tmp_path_factory.mktemp("digests"), P, SEARCHES, "small")
    return path, out


@pytest.fixture
def copy(small, tmp_path):
    shutil.copytree(small[1], tmp_path / "out")
    return tmp_path / "out"


@pytest.fixture(scope="module")
def other(tmp_path_factory):
    """Another configuration (two searches per run, not three), sampled the same way:
    (YAML path, folder); its runs end at the cap, so raising it continues them."""
    _, path, out = sample_small(tmp_path_factory.mktemp("other"), P, 2, "other")
    return path, out


@pytest.fixture(scope="module")
def analysed_once(other, tmp_path_factory):
    """``other`` analysed (with the conditioning): its figures sealed."""
    from lonlib.analysis.pipeline import analyse

    out = tmp_path_factory.mktemp("analysed") / "out"
    shutil.copytree(other[1], out)
    analyse(out, close_figures=True)
    return out


@pytest.fixture
def analysed(analysed_once, tmp_path):
    shutil.copytree(analysed_once, tmp_path / "analysed")
    return tmp_path / "analysed"


def findings(folder: Path) -> list[str]:
    return [str(f) for f in verify_experiment(folder, recordings=False).errors]


def assert_caught(folder: Path, name: str, yaml_path: Path) -> None:
    """verify names ``name``; resume and analysis refuse with one line naming it."""
    errors = findings(folder)
    assert any("[digest]" in e and name in e for e in errors), errors
    with pytest.raises(TamperedDataError, match=f"{name}.*lonlib verify") as caught:
        run_experiment(load_config(yaml_path), folder, progress=False)
    assert "\n" not in str(caught.value)
    with pytest.raises(TamperedDataError, match=name):
        load_experiment(folder)


def test_a_new_experiment_is_sealed_and_verifies(small):
    _, out = small
    assert (out / SEAL_NAME).is_file()
    assert len(list(out.glob(f"p=*/run_*/{RUN_DIGESTS}"))) == 2
    check = check_experiment_seal(out, read_manifest(out))
    assert check.ok and check.pending == [], (check.problems, check.pending)
    report = verify_experiment(out, recordings=False)
    assert report.ok and report.sealed and report.findings == []
    assert read_manifest(out)[SEALED_FIELD] is True


def rewrite_table(folder, run, change):
    path = trials_path(folder, P, run)
    table = pd.read_parquet(path)
    changed = change(table)
    (table if changed is None else changed).to_parquet(path)


def rewrite_optimum(folder, run, index, change):
    path = optimum_path(folder, P, run, index)
    with np.load(path) as data:
        arrays = {k: data[k].copy() for k in data.files}
    change(arrays)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    path.write_bytes(buffer.getvalue())


def ulp(arrays):
    arrays["theta"][3] = np.nextafter(arrays["theta"][3], np.float32(np.inf))


def plus(name, delta):
    def change(arrays):
        arrays[name] = arrays[name] + np.asarray(delta, dtype=arrays[name].dtype)

    return change


TABLE_EDITS = {
    "fitness + 1e-6": lambda t: t.__setitem__("fitness", t["fitness"] + 1e-6),
    "stop_reason": lambda t: t.__setitem__(
        "stop_reason", "patience" if t["stop_reason"].iloc[0] != "patience" else "budget"
    ),
    "env_steps + 1": lambda t: t.__setitem__("env_steps", t["env_steps"] + 1),
    "p + 1 ulp": lambda t: t.__setitem__("p", np.nextafter(t["p"], 1.0)),
}


@pytest.mark.parametrize("edit", list(TABLE_EDITS))
def test_an_edited_trials_table_is_named_and_refused(small, copy, edit):
    rewrite_table(copy, 0, TABLE_EDITS[edit])
    assert_caught(copy, "run_0000/trials.parquet", small[0])


@pytest.mark.parametrize(
    "change",
    [ulp, plus("fitness", 1e-6), plus("omega", 1e-3)],
    ids=["one float32 ulp of the Actor", "the file's own fitness + 1e-6", "the Critic + 1e-3"],
)
def test_an_edited_optimum_is_named_and_refused(small, copy, change):
    rewrite_optimum(copy, 1, 1, change)
    assert_caught(copy, "run_0001/optimum_0001.npz", small[0])


def test_removed_last_trials_are_named_and_refused(small, copy):
    """A careful partial copy: the last trial's row, files and digests entry all removed."""
    folder = run_dir(copy, P, 0)
    rewrite_table(copy, 0, lambda t: t.iloc[:-1])
    for path in folder.glob(f"*_{SEARCHES - 1:04d}.*"):
        path.unlink()
    digests = json.loads((folder / RUN_DIGESTS).read_text())
    digests["trials"] = digests["trials"][:-1]
    (folder / RUN_DIGESTS).write_text(json.dumps(digests))
    assert_caught(copy, "run_0000/trials.parquet", small[0])


def test_a_run_resealed_to_its_count_under_the_earlier_root_is_named(small, copy):
    """A mixed folder: run 0's last trial changed and its digests rebuilt (as sealing
    another copy would), under the root sealed before: the same count, another head."""
    from lonlib.storage.digests import seal_runs

    root = (copy / SEAL_NAME).read_text()
    rewrite_table(copy, 0, lambda t: t.__setitem__("fitness", t["fitness"] + 1e-6))
    seal_runs(copy, read_manifest(copy))
    (copy / SEAL_NAME).write_text(root)
    assert_caught(copy, "run_0000/trials.parquet", small[0])


def test_a_removed_run_and_an_edited_setting_are_named(small, copy):
    manifest = copy / "manifest.json"
    manifest.write_text(manifest.read_text().replace('"tolerance": 2', '"tolerance": 3'))
    assert any("manifest.json" in e for e in findings(copy))
    shutil.rmtree(run_dir(copy, P, 1))
    assert any("run_0001/trials.parquet" in e for e in findings(copy))


def test_the_incumbent_on_resume_is_the_tables_fitness(small, copy):
    """Not the optimum file's second copy: with that copy changed (and the folder resealed,
    so only this rule can tell them apart), f* is still the table's."""
    config = load_config(small[0]).basin_hopping(P)
    incumbent = load_run_state(copy, P, 0, config).incumbent_index
    rewrite_optimum(copy, 0, incumbent, plus("fitness", 0.25))
    reseal(copy)
    state = load_run_state(copy, P, 0, config)
    table = pd.read_parquet(trials_path(copy, P, 0))
    assert state.incumbent.fitness == table["fitness"].iloc[state.incumbent_index]


def unseal(folder: Path) -> None:
    """``folder`` as written before digests: no seal, no run digests, no mark of a seal."""
    (folder / SEAL_NAME).unlink()
    for path in folder.glob(f"p=*/run_*/{RUN_DIGESTS}"):
        path.unlink()
    manifest = json.loads((folder / "manifest.json").read_text())
    del manifest[SEALED_FIELD]
    (folder / "manifest.json").write_text(json.dumps(manifest))


def test_an_unsealed_folder_is_warned_about_then_sealed_by_verify(small, copy, capsys):
    unseal(copy)
    with pytest.warns(UnsealedDataWarning, match="unsealed .* --seal"):
        load_experiment(copy)
    report = verify_experiment(copy, recordings=False)
    assert report.ok and not report.sealed
    assert any("unsealed" in str(f) for f in report.warnings)
    cli_main(["verify", "--seal", str(copy)])
    assert "sealed:" in capsys.readouterr().out
    assert verify_experiment(copy, recordings=False).findings == []
    assert read_manifest(copy)[SEALED_FIELD] is True  # losing the seal now is tampering
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_experiment(copy)


def test_sealing_refuses_a_folder_a_session_is_sampling(small, copy, capsys):
    """``verify --seal`` rewrites the runs' digests that a session appends to: while a session
    holds the sampling lock (shared) it refuses in one line and seals nothing."""
    from lonlib.storage.layout import SAMPLING_LOCK
    from lonlib.storage.lock import SamplingLock

    unseal(copy)
    session = SamplingLock(copy / SAMPLING_LOCK)
    session.acquire(exclusive=False)
    try:
        with pytest.raises(SystemExit):
            cli_main(["verify", "--seal", str(copy)])
    finally:
        session.release()
    assert capsys.readouterr().err.endswith(
        f"lonlib: error: {copy}: a sampling session is running; seal it once it ends\n"
    )
    assert not (copy / SEAL_NAME).exists()
    cli_main(["verify", "--seal", str(copy)])
    assert (copy / SEAL_NAME).is_file()


def test_a_folder_that_fails_verify_is_not_sealed(small, copy):
    (copy / SEAL_NAME).unlink()
    rewrite_table(copy, 0, TABLE_EDITS["fitness + 1e-6"])
    with pytest.raises(SystemExit):
        cli_main(["verify", "--no-recordings", "--seal", str(copy)])
    assert not (copy / SEAL_NAME).exists()


def test_thin_checks_the_seal_then_reseals_what_it_rewrote(small, copy):
    thin_histories(copy)
    assert verify_experiment(copy, recordings=False).findings == []
    rewrite_optimum(copy, 0, 0, ulp)
    with pytest.raises(TamperedDataError, match="optimum_0000.npz"):
        thin_histories(copy)


def test_thin_refuses_a_linked_table(small, copy, tmp_path):
    target = tmp_path / "elsewhere.parquet"
    shutil.copy(trials_path(copy, P, 0), target)
    trials_path(copy, P, 0).unlink()
    trials_path(copy, P, 0).symlink_to(target)
    before = {p: p.read_bytes() for p in run_dir(copy, P, 0).glob("history_*")}
    with pytest.raises(Exception, match="symbolic link"):
        thin_histories(copy)
    assert before == {p: p.read_bytes() for p in run_dir(copy, P, 0).glob("history_*")}


KILLER = """
import os, signal, sys
from fnmatch import fnmatch
from pathlib import Path
import lonlib.storage.atomic as atomic, lonlib.storage._digests_format as digests
import lonlib.storage.trials as trials
from lonlib.config import load_config
from lonlib.experiment.running import run_experiment

pattern, count, original, seen = sys.argv[3], int(sys.argv[4]), atomic.atomic_write, [0]
allow_changes = sys.argv[5].split(",") if len(sys.argv) > 5 else ()

def write_then_maybe_die(path, data):
    original(path, data)
    if fnmatch(Path(path).name, pattern):
        seen[0] += 1
        if seen[0] == count:
            os.kill(os.getpid(), signal.SIGKILL)

for module in (atomic, digests, trials):
    module.atomic_write = write_then_maybe_die
run_experiment(
    load_config(sys.argv[1]), Path(sys.argv[2]), progress=False, allow_changes=allow_changes
)
"""

KILL_POINTS = [
    ("manifest.json", 1),  # the new experiment's manifest, before any trial
    ("history_*.parquet", 3),  # a trial's files written, its row not
    ("optimum_*.npz", 4),
    ("trials.parquet", 2),  # the row written, not yet sealed in the run
    ("trials.parquet", 5),
    (RUN_DIGESTS, 4),  # sealed in the run, not yet in the root
    (SEAL_NAME, 1),  # the root sealed ahead of the new manifest
    ("manifest.json", 2),  # the session's end recorded, the root not yet updated
]


@pytest.mark.parametrize("point", KILL_POINTS, ids=[f"{p}#{n}" for p, n in KILL_POINTS])
def test_a_sigkill_at_each_write_resumes_and_verifies_never_tampered(small, tmp_path, point):
    yaml_path, expected = small
    out = tmp_path / "killed"
    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, str(script), str(yaml_path), str(out), point[0], str(point[1])],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == -signal.SIGKILL, done.stderr[-2000:]
    if (out / "manifest.json").exists():  # what the kill left reads as pending, never tampered
        check = check_experiment_seal(out, read_manifest(out))
        assert check.sealed and check.ok, check.problems
    run_experiment(load_config(yaml_path), out, progress=False)
    for run in range(2):
        assert_frame_equal_bits(trials_path(out, P, run), trials_path(expected, P, run))
    check = check_experiment_seal(out, read_manifest(out))
    assert check.ok and check.pending == [], (check.problems, check.pending)
    assert verify_experiment(out, recordings=False).errors == []


def assert_frame_equal_bits(path, expected):
    columns = ["p", "run", "index", "parent", "fitness", "accepted", "env_steps", "label"]
    got, want = pd.read_parquet(path)[columns], pd.read_parquet(expected)[columns]
    pd.testing.assert_frame_equal(got, want, check_exact=True)


def test_a_deleted_or_renamed_recording_is_named(tmp_path):
    copy = tmp_path / "reference"
    shutil.copytree(COMMITTED[0], copy)
    recordings = sorted((copy / "recordings").glob("*.rrd"))
    recordings[0].unlink()
    renamed = recordings[1].with_name("best_balancing_optimum_p=0.001_run=4_f=0.951.rrd")
    recordings[1].rename(renamed)
    problems = dict(check_experiment_seal(copy, read_manifest(copy)).problems)
    assert problems[f"recordings/{recordings[0].name}"].endswith("is missing")
    assert problems[f"recordings/{recordings[1].name}"].endswith(f"is renamed to {renamed.name}")
    assert problems[f"recordings/{renamed.name}"] == "not in the recordings index"


def test_a_changed_recording_is_named(tmp_path):
    copy = tmp_path / "reference"
    shutil.copytree(COMMITTED[0], copy)
    recording = sorted((copy / "recordings").glob("*.rrd"))[0]
    with open(recording, "ab") as handle:
        handle.write(b"\0")
    problems = dict(check_experiment_seal(copy, read_manifest(copy)).problems)
    assert problems == {
        f"recordings/{recording.name}": "differs from its seal (a recording: `lonlib record` "
        "regenerates it)"
    }


def test_a_study_folder_is_sealed_file_by_file(tmp_path, capsys):
    folder = tmp_path / "study"
    (folder / "cells").mkdir(parents=True)
    (folder / ".gitignore").write_text("*.npz\ninflight/\n")
    (folder / "cells" / "a.json").write_text("{}")
    (folder / "cells" / "a.npz").write_bytes(b"ignored")
    (folder / "study.csv").write_text("x\n1\n")
    assert seal_files(folder) == 2
    cli_main(["verify", str(folder)])
    assert "verify: OK" in capsys.readouterr().out
    (folder / "study.csv").write_text("x\n2\n")
    (folder / "cells" / "b.json").write_text("{}")
    check = check_files_seal(folder)
    assert check.problems == [("study.csv", "differs from its seal")]
    assert [name for name, _ in check.pending] == ["cells/b.json"]
    with pytest.raises(SystemExit):
        cli_main(["verify", str(folder)])


STUDIES = sorted(p.parent for p in (ROOT / "data" / "studies").glob(f"*/{SEAL_NAME}"))


@pytest.mark.parametrize("folder", COMMITTED, ids=lambda p: p.name)
def test_the_committed_experiments_are_sealed_and_match(folder):
    check = check_experiment_seal(folder, read_manifest(folder))
    assert check.sealed and check.ok and check.pending == [], (check.problems, check.pending)


def test_the_committed_study_folders_are_sealed_and_match():
    assert STUDIES, "no sealed study folder"
    for folder in STUDIES:
        check = check_files_seal(folder)
        assert check.ok, (folder, check.problems)


def test_a_deleted_root_seal_of_a_sealed_experiment_is_named_not_unsealed(small, copy):
    (copy / SEAL_NAME).unlink()
    assert any("seal.json: missing, while 2 run(s)" in e for e in findings(copy))
    with pytest.raises(TamperedDataError, match="seal.json"):
        load_experiment(copy)


def test_a_row_appended_by_hand_is_named_and_refused(small, copy):
    rewrite_table(copy, 0, lambda t: pd.concat([t, t.iloc[[-1]].assign(index=len(t))]))
    assert_caught(copy, "run_0000/trials.parquet", small[0])


def test_a_run_added_by_hand_is_named(small, copy):
    shutil.copytree(run_dir(copy, P, 1), run_dir(copy, P, 2))
    (run_dir(copy, P, 2) / RUN_DIGESTS).unlink()
    assert any("run_0002/trials.parquet" in e for e in findings(copy))


def test_a_temporary_or_stray_file_in_a_run_is_no_crash(small, copy):
    folder = run_dir(copy, P, 0)
    (folder / ".optimum_0002.npz.x1y2.tmp").write_bytes(b"half")
    (folder / "history_0001.parquet.bak").write_bytes(b"copy")
    assert verify_experiment(copy, recordings=False).errors == []
    load_experiment(copy)


@pytest.mark.parametrize(
    "shape",
    [{"runs": []}, {"runs": {"p=0.001/run_0000": 3}}, {"recordings": {"a.rrd": 1}}],
    ids=["runs a list", "a run an int", "a recording an int"],
)
def test_a_malformed_seal_is_one_line_naming_it(small, copy, shape):
    seal = json.loads((copy / SEAL_NAME).read_text())
    (copy / SEAL_NAME).write_text(json.dumps({**seal, **shape}))
    with pytest.raises(TamperedDataError, match="seal.json: not a well-formed seal"):
        load_experiment(copy)
    assert any("seal.json" in e for e in findings(copy))


DIGEST = "0" * 64
LONG_PATH = "figures/" + "/".join(["a" * 255] * 16)[: 4097 - len("figures/")]
"""A figure key of 4097 characters, each of its names 255 bytes or fewer."""


@pytest.mark.parametrize(
    "field, shape",
    [
        ("figures.next", {"figures": {"next": {"files": {"figures/../manifest.json": None}}}}),
        ("figures.next", {"figures": {"next": {"files": {"/etc/passwd": DIGEST}}}}),
        ("figures.next", {"figures": {"next": {"files": {"p=0.001/trials.parquet": None}}}}),
        ("figures.next", {"figures": {"next": {"files": {"figures": None}}}}),
        ("recordings_next", {"recordings_next": {"../seal.json": {"sha256": DIGEST}}}),
        ("recordings_next", {"recordings_next": {"a/b.rrd": {"sha256": DIGEST}}}),
        ("recordings_next", {"recordings_next": {"..": {"sha256": DIGEST}}}),
        ("figures.files", {"figures": {"files": {"/etc/passwd": DIGEST}}}),
        ("figures.files", {"figures": {"files": {"../../etc/hostname": DIGEST}}}),
        ("figures.inputs_of", {"figures": {"inputs_of": {"figures/../seal.json": None}}}),
        ("recordings", {"recordings": {"../seal.json": {"sha256": DIGEST}}}),
        ("figures.next", {"figures": {"next": {"files": {"figures/" + "a" * 5000: None}}}}),
        ("figures.next", {"figures": {"next": {"files": {LONG_PATH: None}}}}),
        ("recordings", {"recordings": {"é" * 126 + ".rrd": {"sha256": DIGEST}}}),
    ],
    ids=[
        "figure ..",
        "figure absolute",
        "figure elsewhere",
        "the folder",
        "recording ../",
        "recording in a folder",
        "recording named ..",
        "settled figure absolute",
        "settled figure ../",
        "figure drawn from ..",
        "settled recording ../",
        "figure name of 5000 characters",
        "figure path of 4097 characters",
        "recording name of 256 bytes",
    ],
)
def test_a_seal_ahead_naming_a_file_outside_its_folder_is_malformed(small, copy, field, shape):
    """The outputs sealed (ahead or settled) name files under ``figures/`` (relative, no
    ``..``) and plain recording names, each name at most 255 bytes and each path at most 4096
    characters: any other key is the seal's shape error naming the field."""
    seal = json.loads((copy / SEAL_NAME).read_text())
    (copy / SEAL_NAME).write_text(json.dumps({**seal, **shape}))
    with pytest.raises(TamperedDataError, match=f"seal.json: not a well-formed seal.*'{field}'"):
        load_experiment(copy)
    assert any("seal.json" in e and field in e for e in findings(copy))


def test_names_at_the_length_bounds_are_well_formed():
    """A 255-byte name (two-byte characters) and a 4096-character figure key are accepted."""
    from lonlib.storage._digests_format import _shape_problem

    name = "é" * 125 + "x.rrd"
    assert len(name.encode()) == 255
    assert _shape_problem({"recordings": {name: {"sha256": DIGEST}}}, False) is None
    key = LONG_PATH[:4096]
    assert len(key) == 4096
    figures = {"files": {key: DIGEST}, "inputs_of": {key: None}, "next": {"files": {key: None}}}
    assert _shape_problem({"figures": figures}, False) is None


def test_a_malformed_run_digests_is_one_line_naming_it(small, copy):
    (run_dir(copy, P, 0) / RUN_DIGESTS).write_text('{"format": 1, "trials": "x"}')
    with pytest.raises(TamperedDataError, match="digests.json: not a well-formed seal"):
        load_experiment(copy)


def test_sealing_without_replaying_the_recordings_is_refused(small, copy, capsys):
    (copy / SEAL_NAME).unlink()
    with pytest.raises(SystemExit):
        cli_main(["verify", "--no-recordings", "--seal", str(copy)])
    assert "without --no-recordings" in capsys.readouterr().err


def test_an_experiment_whose_manifest_is_gone_does_not_verify(small, copy):
    (copy / "manifest.json").unlink()
    with pytest.raises(SystemExit):
        cli_main(["verify", str(copy)])
    with pytest.raises(ValueError, match="experiment's folder"):
        seal_files(copy)


def test_thin_refuses_a_linked_run_folder(small, copy, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    shutil.move(run_dir(copy, P, 0), elsewhere)
    run_dir(copy, P, 0).symlink_to(elsewhere)
    with pytest.raises(Exception, match="symbolic link"):
        thin_histories(copy)


def test_a_thin_killed_part_way_is_accepted_and_completed_by_the_next(small, copy):
    from lonlib.storage.digests import bytes_digest, seal_ahead

    path = sorted(copy.glob("p=*/run_*/history_*.parquet"))[0]
    table = pd.read_parquet(path)
    new = table.iloc[-1:].to_parquet(index=False)
    seal_ahead(copy, {path: bytes_digest(new)})
    path.write_bytes(new)  # killed here: rewritten, not yet resealed
    assert check_experiment_seal(copy, read_manifest(copy)).ok
    thin_histories(copy)
    assert verify_experiment(copy, recordings=False).findings == []
    assert "next" not in (path.parent / RUN_DIGESTS).read_text()


def test_a_stored_policy_checks_the_seal_and_carries_the_tables_fitness(small, copy):
    from lonlib.storage import load_policy

    rewrite_optimum(copy, 0, 1, plus("fitness", 0.25))
    with pytest.raises(TamperedDataError, match="optimum_0001.npz"):
        load_policy(copy, P, 0, 1)
    reseal(copy)
    table = pd.read_parquet(trials_path(copy, P, 0))
    assert load_policy(copy, P, 0, 1).fitness == table["fitness"].iloc[1]


def test_a_sealed_folder_that_lost_its_seal_and_every_digest_is_refused_not_unsealed(
    small, copy, capsys
):
    """The manifest records the seal: removing it and every run's digests is tampering
    (named, refused), not a folder written before digests; `verify --seal` after a full
    replay is still the way to accept a deliberate change."""
    (copy / SEAL_NAME).unlink()
    for path in copy.glob(f"p=*/run_*/{RUN_DIGESTS}"):
        path.unlink()
    assert any("seal.json: missing, while the manifest" in e for e in findings(copy))
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnsealedDataWarning)
        with pytest.raises(TamperedDataError, match="seal.json: missing") as caught:
            load_experiment(copy)
    assert "\n" not in str(caught.value)
    cli_main(["verify", "--seal", str(copy)])
    assert "sealed:" in capsys.readouterr().out
    assert verify_experiment(copy, recordings=False).findings == []


def move_in_other_run(copy: Path, other: Path) -> Path:
    """``copy`` resealed without its run 1, then ``other``'s run 1 (the same name, another
    configuration) moved in with its digests: the run's digests.json."""
    shutil.rmtree(run_dir(copy, P, 1))
    reseal(copy)
    shutil.copytree(run_dir(other, P, 1), run_dir(copy, P, 1))
    return run_dir(copy, P, 1) / RUN_DIGESTS


def test_a_run_moved_in_from_an_experiment_of_another_configuration_is_named(small, other, copy):
    """Not in the root, its chain whole: before chains started from the configuration it
    read as a session's trials not yet in the root."""
    move_in_other_run(copy, other[1])
    assert_caught(copy, "run_0001/digests.json", small[0])


def test_a_moved_run_relabelled_with_this_configuration_has_a_broken_chain(small, other, copy):
    digests = move_in_other_run(copy, other[1])
    payload = json.loads(digests.read_text())
    payload["config"] = json.loads((copy / SEAL_NAME).read_text())["chain_config"]
    digests.write_text(json.dumps(payload))
    assert any("run_0001/digests.json: its chain" in e for e in findings(copy))
    assert_caught(copy, "run_0001/digests.json", small[0])


def more_trials(folder: Path, yaml_path: Path) -> None:
    """Raise ``other``'s cap from 2 to 3 searches: each run goes on by one."""
    import dataclasses

    config = dataclasses.replace(load_config(yaml_path), max_local_searches=3)
    run_experiment(config, folder, progress=False, allow_changes=["max_local_searches"])


def sealed_figures(folder: Path) -> dict:
    return json.loads((folder / SEAL_NAME).read_text())["figures"]


def stale_note(folder: Path) -> str:
    pending = dict(check_experiment_seal(folder, read_manifest(folder)).pending)
    return pending.get("figures", "")


def test_an_analysis_without_the_conditioning_keeps_the_earlier_figures_sealed(analysed):
    from lonlib.analysis.pipeline import analyse

    written = analyse(analysed, close_figures=True, conditioning=False).files
    assert "figures/replayed.csv" not in {f.relative_to(analysed).as_posix() for f in written}
    assert "figures/replayed.csv" in sealed_figures(analysed)["files"]
    check = check_experiment_seal(analysed, read_manifest(analysed))
    assert check.ok and check.pending == [], (check.problems, check.pending)


def test_a_figure_the_seal_does_not_list_is_named(analysed):
    (analysed / "figures" / "extra.png").write_bytes(b"drawn by hand")
    (analysed / "figures" / "other.html").write_text("<html>")  # HTML pages are not sealed
    (analysed / "figures" / ".claims.csv.x1.tmp").write_text("half")  # nor temporaries
    errors = findings(analysed)
    assert [e for e in errors if "figures/" in e] == [
        "error: [digest] figures/extra.png: a figure or table the seal does not list (added "
        "by hand, or written by an analysis that stopped before sealing it: `lonlib analyse` "
        "again)"
    ]


def test_an_edited_or_missing_figure_is_named(analysed):
    with open(analysed / "figures" / "metrics.csv", "a") as table:
        table.write("1,2\n")
    (analysed / "figures" / "fig2_optima_boxplot.png").unlink()
    problems = dict(check_experiment_seal(analysed, read_manifest(analysed)).problems)
    assert problems == {
        "figures/metrics.csv": "differs from its seal (a figure: `lonlib analyse` regenerates it)",
        "figures/fig2_optima_boxplot.png": "a sealed figure or table is missing (`lonlib analyse` "
        "regenerates it)",
    }


def test_figures_drawn_from_earlier_trials_stay_stale_until_analysed_again(other, analysed, capsys):
    """More trials make every figure stale; `verify --seal` seals them as drawn from the
    earlier trials (still stale); an analysis without the conditioning refreshes all but
    the conditioning's files, a full one all."""
    from lonlib.analysis.pipeline import analyse

    listed = len(sealed_figures(analysed)["files"])
    more_trials(analysed, other[0])
    assert stale_note(analysed).startswith(f"{listed} of {listed} figures and tables")
    cli_main(["verify", "--seal", str(analysed)])
    assert "sealed:" in capsys.readouterr().out
    assert stale_note(analysed).startswith(f"{listed} of {listed} figures and tables")
    written = analyse(analysed, close_figures=True, conditioning=False).files
    kept = set(sealed_figures(analysed)["files"]) - {
        f.relative_to(analysed).as_posix() for f in written
    }
    assert "figures/replayed.csv" in kept
    assert set(sealed_figures(analysed)["inputs_of"]) == kept
    assert stale_note(analysed).startswith(f"{len(kept)} of {listed} figures and tables")
    analyse(analysed, close_figures=True)
    assert stale_note(analysed) == "" and "inputs_of" not in sealed_figures(analysed)


def test_figures_are_sealed_as_drawn_from_the_trials_the_analysis_loaded(other, tmp_path):
    """A session appends a trial to each run between the analysis's load of the trials and
    its seal: the figures are sealed as drawn from the trials it loaded (stale, a warning),
    not from those the runs' chains hold at the seal."""
    from lonlib.analysis.landscape import StoredExperiment
    from lonlib.analysis.pipeline import analyse
    from lonlib.storage._digests_format import inputs_now

    out = tmp_path / "out"
    shutil.copytree(other[1], out)
    experiment = StoredExperiment.load(out)
    loaded = inputs_now(out, json.loads((out / SEAL_NAME).read_text()))
    more_trials(out, other[0])
    analyse(experiment, close_figures=True, conditioning=False)
    figures = sealed_figures(out)
    assert figures["inputs"] == loaded and "inputs_of" not in figures
    assert loaded != inputs_now(out, json.loads((out / SEAL_NAME).read_text()))
    listed = len(figures["files"])
    assert stale_note(out).startswith(f"{listed} of {listed} figures and tables")
    assert verify_experiment(out, recordings=False).errors == []


def test_the_loaded_inputs_name_the_chain_at_the_count_read(other, tmp_path, monkeypatch):
    """A trial sealed in a run's ``digests.json`` after the reader read its trials table:
    the loaded inputs name the chain head at the count the reader read, not the newest."""
    from lonlib.analysis.landscape import StoredExperiment
    from lonlib.storage import _digests_format
    from lonlib.storage._digests_format import inputs_now, loaded_inputs

    out = tmp_path / "out"
    shutil.copytree(other[1], out)
    experiment = StoredExperiment.load(out)
    expected = inputs_now(out, json.loads((out / SEAL_NAME).read_text()))
    assert loaded_inputs(out, experiment.trials) == expected
    read_run = _digests_format.read_run

    def sealed_meanwhile(path, *args, **kwargs):
        entries, *rest = read_run(path, *args, **kwargs)
        return (entries + [{**entries[-1], "chain": "f" * 64}], *rest)

    monkeypatch.setattr(_digests_format, "read_run", sealed_meanwhile)
    assert loaded_inputs(out, experiment.trials) == expected


CHANGE_POINTS = [
    (SEAL_NAME, 1),  # the root sealed ahead of the manifest with the changed setting
    ("manifest.json", 1),  # the manifest written, the root not yet
]


@pytest.mark.parametrize("point", CHANGE_POINTS, ids=[f"{p}#{n}" for p, n in CHANGE_POINTS])
def test_a_sigkill_around_a_changed_setting_leaves_either_accepted(other, tmp_path, point):
    """A session that raises ``max_local_searches`` seals the new configuration ahead of the
    manifest (``config_next``): killed after either write, the folder is not tampered, and
    resuming completes it."""
    import dataclasses

    import yaml

    out = tmp_path / "changed"
    shutil.copytree(other[1], out)
    config = dataclasses.replace(load_config(other[0]), max_local_searches=3)
    yaml_path = tmp_path / "raised.yaml"
    yaml_path.write_text(yaml.safe_dump(config.to_dict()))
    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    argv = [str(script), str(yaml_path), str(out), point[0], str(point[1]), "max_local_searches"]
    done = subprocess.run(
        [sys.executable, *argv], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == -signal.SIGKILL, done.stderr[-2000:]
    check = check_experiment_seal(out, read_manifest(out))
    assert check.ok, check.problems
    run_experiment(config, out, progress=False, allow_changes=["max_local_searches"])
    check = check_experiment_seal(out, read_manifest(out))
    assert check.ok and check.pending == [], (check.problems, check.pending)


def test_status_says_a_folder_is_tampered_and_still_shows_it(small, copy, capsys):
    from lonlib.experiment.running import status

    rewrite_table(copy, 0, TABLE_EDITS["fitness + 1e-6"])
    with pytest.warns(TamperedDataWarning, match=r"run_0000/trials.parquet.*`lonlib status`"):
        status(copy)
    for argv in (["status", str(copy), "--runs"], ["status", str(copy), "--dry-run"]):
        cli_main(argv)
        out, err = capsys.readouterr()
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("lonlib: warning: "), err
        assert "run_0000/trials.parquet" in lines[0] and "lonlib verify" in lines[0]
    cli_main(["status", str(copy)])
    assert "finished" in capsys.readouterr().out


def test_the_fitness_scale_checks_what_it_reads(small, copy, tmp_path, monkeypatch):
    from lonlib.analysis import fitness_scale

    study = tmp_path / "study"
    study.mkdir()
    np.save(study / "actor.npy", np.zeros(3))
    seal_files(study)
    monkeypatch.setattr(fitness_scale, "EXPERIMENTS", ("out",))
    monkeypatch.setattr(fitness_scale, "BALANCING_ACTOR", "study/actor.npy")
    rewrite_table(copy, 0, TABLE_EDITS["fitness + 1e-6"])
    with pytest.raises(TamperedDataError, match="run_0000/trials.parquet.*fitness_scale"):
        fitness_scale.fitness_scale_markdown(tmp_path)
    reseal(copy)
    np.save(study / "actor.npy", np.ones(3))
    with pytest.raises(TamperedDataError, match="actor.npy: differs"):
        fitness_scale.fitness_scale_markdown(tmp_path)


@pytest.mark.parametrize("verb", ["lon", "analyse", "record", "thin", "run"])
def test_a_reader_that_refuses_names_its_command(small, copy, verb, capsys):
    rewrite_table(copy, 0, TABLE_EDITS["fitness + 1e-6"])
    runs = [["run", str(small[0]), "--out", str(copy)]]
    argvs = runs if verb == "run" else [[verb, str(copy)], [verb, str(copy), "--dry-run"]]
    if verb == "run":
        argvs += [[*runs[0], "--dry-run"]]
    for argv in argvs:
        with pytest.raises(SystemExit):
            cli_main(argv)
        err = capsys.readouterr().err
        assert "run_0000/trials.parquet" in err and f"`lonlib {verb}` stops" in err, argv


def drop_last_trial(folder: Path, run: int, keep_digests: bool = True) -> None:
    """A run's last row and its files removed (its digests entry kept, unless not
    ``keep_digests``)."""
    rewrite_table(folder, run, lambda t: t.iloc[:-1])
    for path in run_dir(folder, P, run).glob(f"*_{SEARCHES - 1:04d}.*"):
        path.unlink()
    if not keep_digests:
        path = run_dir(folder, P, run) / RUN_DIGESTS
        digests = json.loads(path.read_text())
        digests["trials"] = digests["trials"][:-1]
        path.write_text(json.dumps(digests))


@pytest.mark.parametrize("change", ["critic", "last trial", "both"])
def test_a_change_under_a_deleted_root_seal_is_named_and_not_sealed(small, copy, change, capsys):
    """Deleting only seal.json does not make --seal accept what the runs' digests refuse."""
    if change in ("critic", "both"):
        rewrite_optimum(copy, 1, 1, plus("omega", 1e-3))
    if change in ("last trial", "both"):
        drop_last_trial(copy, 0)
    (copy / SEAL_NAME).unlink()
    errors = findings(copy)
    if change in ("critic", "both"):
        assert any("run_0001/optimum_0001.npz: differs from its seal" in e for e in errors)
    if change in ("last trial", "both"):
        assert any("run_0000/trials.parquet: holds 2 trials" in e for e in errors), errors
    assert not any("seal.json: missing, while" in e for e in errors), errors
    with pytest.raises(SystemExit):
        cli_main(["verify", "--seal", str(copy)])
    assert not (copy / SEAL_NAME).exists()
    with pytest.raises(TamperedDataError):
        load_experiment(copy)


def test_a_seal_interrupted_before_its_root_is_completed_by_sealing_again(small, copy, capsys):
    (copy / SEAL_NAME).unlink()  # runs sealed, the root not yet, nothing changed
    assert findings(copy) == [
        "error: [digest] seal.json: missing, while 2 run(s) hold their digests"
    ]
    cli_main(["verify", "--seal", str(copy)])
    assert "sealed:" in capsys.readouterr().out
    assert verify_experiment(copy, recordings=False).findings == []


def test_sealing_a_study_folder_whose_files_differ_is_refused(tmp_path, capsys):
    """``--seal`` verifies first: an edited file is not sealed over (never silently); a
    deliberate change is accepted by deleting seal.json, then sealing."""
    folder = tmp_path / "study"
    folder.mkdir()
    (folder / "calibration.csv").write_text("x\n1\n")
    seal_files(folder)
    sealed = (folder / SEAL_NAME).read_text()
    (folder / "calibration.csv").write_text("x\n2\n")
    with pytest.raises(SystemExit):
        cli_main(["verify", "--seal", str(folder)])
    assert "calibration.csv: differs from its seal" in capsys.readouterr().out
    assert (folder / SEAL_NAME).read_text() == sealed
    (folder / SEAL_NAME).unlink()
    cli_main(["verify", "--seal", str(folder)])
    cli_main(["verify", str(folder)])
    assert "verify: OK" in capsys.readouterr().out


def test_removed_last_rows_and_files_under_kept_digests_are_named_and_refused(small, copy):
    """A run's last row and files removed, its digests.json kept: named against the root's
    count (not read as a trial sealed ahead), and resuming refuses rather than re-sampling."""
    drop_last_trial(copy, 0)
    errors = findings(copy)
    assert any("run_0000/trials.parquet: holds 2 trials, the seal holds 3" in e for e in errors)
    assert_caught(copy, "run_0000/trials.parquet", small[0])
    assert len(pd.read_parquet(trials_path(copy, P, 0))) == SEARCHES - 1  # nothing re-sampled


@pytest.mark.parametrize("name", ["history_0001.parquet", "optimum_0001.npz"])
def test_a_deleted_sealed_file_is_named(small, copy, name):
    """Histories are not replayed: only the digest names a deleted one."""
    (run_dir(copy, P, 1) / name).unlink()
    errors = findings(copy)
    assert f"error: [digest] p=0.001/run_0001/{name}: a sealed file is missing" in errors, errors
    assert_caught(copy, f"run_0001/{name}", small[0])


def test_an_extra_file_no_seal_lists_is_named(small, copy):
    folder = run_dir(copy, P, 0)
    shutil.copy(folder / "optimum_0001.npz", folder / "optimum_00001.npz")
    errors = findings(copy)
    assert "error: [digest] p=0.001/run_0000/optimum_00001.npz: a file no seal lists" in errors
    assert_caught(copy, "run_0000/optimum_00001.npz", small[0])


def set_versions(folder: Path, version: str) -> None:
    manifest = json.loads((folder / "manifest.json").read_text())
    for session in manifest["sessions"]:
        session["result_path_version"] = version
    (folder / "manifest.json").write_text(json.dumps(manifest))


def test_the_sessions_result_path_versions_are_sealed(small, copy):
    """They decide whether a replay mismatch is an error: an older one stamped by hand on
    a sealed folder (turning errors into warnings) is named."""
    assert json.loads((copy / SEAL_NAME).read_text())["result_path_versions"] == ["2"]
    set_versions(copy, "1")
    assert any("manifest.json: its sessions' result-path versions" in e for e in findings(copy))
    with pytest.raises(TamperedDataError, match="manifest.json"):
        load_experiment(copy)


def test_a_root_sealed_before_the_versions_were_sealed_reads_as_before(small, copy):
    seal = json.loads((copy / SEAL_NAME).read_text())
    del seal["result_path_versions"]
    (copy / SEAL_NAME).write_text(json.dumps(seal))
    assert check_experiment_seal(copy, read_manifest(copy)).ok


def test_sealing_refuses_mismatches_reported_as_warnings(small, copy, capsys):
    """An unsealed folder stamped with an older version: its mismatches are warnings, and
    ``--seal`` still refuses to seal numbers that do not replay."""
    unseal(copy)
    set_versions(copy, "1")
    rewrite_table(copy, 0, TABLE_EDITS["fitness + 1e-6"])
    report = verify_experiment(copy, recordings=False)
    assert report.ok and any(f.check == "fitness" for f in report.warnings)
    with pytest.raises(SystemExit):
        cli_main(["verify", "--seal", str(copy)])
    assert "not sealed: stored numbers do not replay" in capsys.readouterr().out
    assert not (copy / SEAL_NAME).exists()


def test_a_record_killed_before_its_reseal_is_repaired_by_recording_again(small, copy):
    """``record`` rewrote a recording in place (as an older lonlib did), then was killed before
    resealing it: verify says `lonlib record` regenerates it, and recording again does (its
    own output); a recording it would not write stays a refusal."""
    from lonlib.analysis.pipeline import record_optima

    (path,) = record_optima(copy, limit=1)
    with open(path, "ab") as handle:
        handle.write(b"\0")  # as a rewrite the reseal did not follow
    problems = dict(check_experiment_seal(copy, read_manifest(copy)).problems)
    assert "`lonlib record` regenerates it" in problems[f"recordings/{path.name}"]
    assert record_optima(copy, limit=1) == [path]
    assert check_experiment_seal(copy, read_manifest(copy)).ok
    shutil.copy(path, path.with_name("planted.rrd"))
    with pytest.raises(TamperedDataError, match="planted.rrd"):
        record_optima(copy, limit=1)
