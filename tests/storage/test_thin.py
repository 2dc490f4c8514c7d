"""Thinning an experiment's training histories (``lonlib thin``): the judged rows and the
last row stay, every other stored file is untouched, and the folder still verifies."""

import io
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from lonlib.analysis.verify import verify_experiment
from lonlib.cli import main
from lonlib.storage import thin_histories
from lonlib.storage.atomic import MissingExperimentError
from lonlib.storage.layout import SAMPLING_LOCK
from lonlib.storage.lock import SamplingLock
from lonlib.storage.thin import HISTORY_GLOB, thinned_history
from tests.conftest import reseal


def test_a_thinned_history_keeps_the_judged_rows_and_the_last_in_order():
    history = pd.DataFrame(
        {
            "episode": range(6),
            "env_steps": [10, 20, 2000, 2050, 4000, 4030],
            "greedy_fitness": [np.nan, np.nan, 0.1, np.nan, 0.3, np.nan],
        }
    )
    kept = thinned_history(history)
    assert list(kept["episode"]) == [2, 4, 5]
    assert kept["greedy_fitness"].iloc[:2].tolist() == [0.1, 0.3]
    assert thinned_history(kept).equals(kept)  # idempotent
    assert thinned_history(history.iloc[:0]).empty
    with pytest.raises(ValueError, match="greedy_fitness"):
        thinned_history(history.drop(columns="greedy_fitness"))


def _files(root):
    return {p.relative_to(root): p.read_bytes() for p in root.rglob("*") if p.is_file()}


def test_thinning_changes_only_the_histories_and_the_folder_still_verifies(
    tiny_experiment, tmp_path
):
    _, folder, _ = tiny_experiment
    root = tmp_path / "exp"
    shutil.copytree(folder, root)
    # make some rows unjudged, as judge_every > 0 leaves them
    for path in sorted(root.glob(HISTORY_GLOB)):
        history = pd.read_parquet(path)
        history.loc[history.index[:-1:2], "greedy_fitness"] = np.nan
        history.to_parquet(path, index=False)
    reseal(root)  # as a search with judge_every > 0 stores it
    before = _files(root)
    histories = {p.relative_to(root) for p in root.glob(HISTORY_GLOB)}
    assert histories
    dry = thin_histories(root, dry_run=True)
    assert _files(root) == before and dry.thinned == dry.files == len(histories)
    report = thin_histories(root)
    assert (report.rows_after, report.bytes_after) == (dry.rows_after, dry.bytes_after)
    assert report.rows_after < report.rows_before and report.bytes_after < report.bytes_before
    after = _files(root)
    assert after.keys() == before.keys()
    resealed = {Path("seal.json")} | {h.parent / "digests.json" for h in histories}
    assert {k for k in after if after[k] != before[k]} == histories | resealed
    for name in histories:
        old = pd.read_parquet(io.BytesIO(before[name]))
        keep = old["greedy_fitness"].notna().to_numpy().copy()
        keep[-1] = True
        assert not keep.all()
        expected = old[keep].reset_index(drop=True)
        pd.testing.assert_frame_equal(pd.read_parquet(root / name), expected)
    assert thin_histories(root).thinned == 0
    report = verify_experiment(root)
    assert report.ok, report.findings


def test_the_thin_command_dry_run_writes_nothing_and_the_real_one_thins(
    tiny_experiment, tmp_path, capsys
):
    _, folder, _ = tiny_experiment
    root = tmp_path / "exp"
    shutil.copytree(folder, root)
    path = sorted(root.glob(HISTORY_GLOB))[0]
    history = pd.read_parquet(path)
    history.loc[history.index[0], "greedy_fitness"] = np.nan
    history.to_parquet(path, index=False)
    before = _files(root)
    main(["thin", str(root), "--dry-run"])
    assert capsys.readouterr().out.startswith("would thin ")
    assert _files(root) == before
    main(["thin", str(root)])
    assert capsys.readouterr().out.startswith("thinned ")
    assert _files(root) != before
    assert len(pd.read_parquet(path)) == len(history) - 1


def test_a_history_without_a_greedy_fitness_is_named(tiny_experiment, tmp_path):
    _, folder, _ = tiny_experiment
    root = tmp_path / "exp"
    shutil.copytree(folder, root)
    path = sorted(root.glob(HISTORY_GLOB))[0]
    pd.read_parquet(path).drop(columns="greedy_fitness").to_parquet(path, index=False)
    reseal(root)
    with pytest.raises(ValueError, match=f"{path.name}: a training history must have"):
        thin_histories(root)


def test_thin_refuses_a_folder_without_an_experiment(tmp_path, capsys):
    with pytest.raises(MissingExperimentError):
        thin_histories(tmp_path)
    with pytest.raises(SystemExit):
        main(["thin", str(tmp_path / "nothing")])


def test_thin_refuses_a_folder_a_session_is_sampling_and_thins_it_once_it_ended(
    tiny_experiment, tmp_path, capsys
):
    """Thin rewrites the runs' digests that a session appends to: while a session holds the
    sampling lock (shared) it refuses in one line and changes nothing."""
    _, folder, _ = tiny_experiment
    root = tmp_path / "exp"
    shutil.copytree(folder, root)
    path = sorted(root.glob(HISTORY_GLOB))[0]
    history = pd.read_parquet(path)
    history.loc[history.index[0], "greedy_fitness"] = np.nan
    history.to_parquet(path, index=False)
    reseal(root)
    session = SamplingLock(root / SAMPLING_LOCK)
    session.acquire(exclusive=False)
    before = _files(root)
    try:
        with pytest.raises(SystemExit):
            main(["thin", str(root)])
    finally:
        session.release()
    assert capsys.readouterr().err == (
        f"lonlib: error: {root}: a sampling session is running; thin it once it ends\n"
    )
    assert _files(root) == before
    main(["thin", str(root)])
    assert len(pd.read_parquet(path)) == len(history) - 1
