"""Impossible input gets a one-line error before any folder is made: a run that cannot fit
in memory, a replay buffer past what a search can use, an --out that is a dangling link."""

import dataclasses

import pytest

from lonlib.cli import main as cli_main
from lonlib.config import DDPGConfig, load_config
from lonlib.experiment.admission import check_memory, search_memory_bytes
from lonlib.experiment.running import run_experiment
from tests.conftest import write_tiny_yaml


@pytest.fixture
def tiny(tmp_path):
    return load_config(write_tiny_yaml(tmp_path))


def test_a_run_that_cannot_fit_in_memory_is_refused_before_its_folder(tiny, tmp_path):
    huge = dataclasses.replace(tiny, ddpg=dataclasses.replace(tiny.ddpg, batch_size=10**9))
    out = tmp_path / "out"
    with pytest.raises(MemoryError, match=r"ddpg\.buffer_size=500 and ddpg\.batch_size=1000000000"):
        run_experiment(huge, out, progress=False)
    assert not out.exists()


def test_the_dry_run_refuses_it_too_in_one_line(tiny, tmp_path, capsys):
    path = tmp_path / "huge.yaml"
    path.write_text(
        write_tiny_yaml(tmp_path).read_text().replace("batch_size: 32", "batch_size: 1000000000")
    )
    with pytest.raises(SystemExit):
        cli_main(["run", str(path), "--out", str(tmp_path / "out"), "--dry-run"])
    error = capsys.readouterr().err.strip()
    assert error.startswith("lonlib: error: ddpg.buffer_size") and "\n" not in error
    assert not (tmp_path / "out").exists()


def test_the_estimate_counts_every_search_held_at_once(tiny):
    one = search_memory_bytes(tiny.env, tiny.ddpg)
    check_memory(tiny, 4, available=int(8 * one))
    with pytest.raises(MemoryError, match="for 5 local search"):
        check_memory(tiny, 5, available=int(8 * one))


def test_a_replay_buffer_past_what_a_search_can_use_is_refused():
    with pytest.raises(ValueError, match="buffer_size"):
        DDPGConfig(buffer_size=2**31 - 1)
    DDPGConfig(buffer_size=100_000_000)


def test_an_out_that_is_a_dangling_link_is_named(tiny, tmp_path, capsys):
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "nowhere")
    with pytest.raises(SystemExit):
        cli_main(["run", str(write_tiny_yaml(tmp_path)), "--out", str(link)])
    error = capsys.readouterr().err
    assert "symbolic link" in error and "nowhere" in error and "File exists" not in error
    assert not (tmp_path / "nowhere").exists()
