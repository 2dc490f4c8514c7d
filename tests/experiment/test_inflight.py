"""In-flight checkpoints are data, not code: tensors read with weights_only=True and JSON,
a format version, hostile or damaged files refused without running anything, and no tie to
module paths or class names."""

import dataclasses
import io
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

import lonlib
from lonlib.ddpg.checkpoint import to_checkpoint
from lonlib.ddpg.slots import JUDGE_BATCH
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.experiment.checkpoints import (
    StoredBatch,
    check_settings,
    load_inflight,
    read_inflight,
    remove_inflight,
    remove_leftovers,
    save_inflight,
    split_inflight,
)
from lonlib.experiment.running import run_experiment
from lonlib.experiment.runs import experiment_plan
from lonlib.storage.inflight import FORMAT, OtherSettings, inflight_checkpoints, new_checkpoint_path
from lonlib.storage.status import run_status
from lonlib.task.policy import actor_spec, critic_spec
from tests.experiment.test_lockstep import CONFIG, SMALL, serial, small_killed, stored

__all__ = ["serial", "small_killed"]  # the fixtures, shared with test_lockstep.py
P = 1e-3
TAGS = [(P, 0), (P, 1), (P, 2)]


class Planted:
    """Unpickling this creates ``path``: the callable a hostile checkpoint would carry."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (open, (str(self.path), "w"))


def mid_search_trainer() -> SlotTrainer:
    """Three searches of one cart mid-way, one slot free since: greedy evaluations are
    queued, environments carry start noise."""
    rng = np.random.default_rng(0)
    thetas = rng.uniform(-0.3, 0.3, (3, actor_spec(1).n_params))
    omegas = rng.uniform(-0.3, 0.3, (3, critic_spec(1).n_params))
    trainer = SlotTrainer(thetas, omegas, [5, 6, 7], CONFIG.env, CONFIG.ddpg, tags=TAGS)
    trainer.judge_batch = JUDGE_BATCH  # evaluations stay queued: the checkpoint carries them
    for _ in range(125):
        assert not trainer.step()
    trainer.drop([1])  # as a restored batch drops a run that went on: a free slot
    assert trainer.pending and list(trainer.busy) == [True, False, True]
    return trainer


def write_checkpoint(out: Path, trainer: SlotTrainer):
    """``trainer`` saved as an in-flight checkpoint of experiment folder ``out``."""
    (out / ".inflight").mkdir(parents=True, exist_ok=True)
    path = new_checkpoint_path(out)
    save_inflight(path, trainer, dict.fromkeys(TAGS, 0))
    (checkpoint,) = inflight_checkpoints(out)
    return checkpoint


def finish(trainer: SlotTrainer) -> dict:
    """Train to the end: every search's result, without its timings."""
    ended = {}
    while trainer.busy.any():
        for tag, result in trainer.step():
            ended[tag] = result
    return {tag: comparable(result) for tag, result in ended.items()}


def comparable(result) -> dict:
    """A result's numbers (exact; NaN equal to NaN) without its timings."""
    history = [{**vars(r), "seconds": 0.0} for r in result.history]
    return {
        "fitness": result.fitness,
        "env_steps": result.env_steps,
        "updates": result.updates,
        "stop_reason": result.stop_reason,
        "theta": result.theta.tobytes(),
        "omega": result.omega.tobytes(),
        "history": json.dumps(history),  # NaN == NaN as text
    }


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A checkpoint of a batch mid-search, the batch's uninterrupted results, and the
    batch at its end."""
    out = tmp_path_factory.mktemp("written")
    trainer = mid_search_trainer()
    checkpoint = write_checkpoint(out, trainer)
    return checkpoint, finish(trainer), trainer


def is_plain(value) -> bool:
    """Only JSON's kinds: nothing that names a Python class."""
    if isinstance(value, dict):
        return all(isinstance(k, str) and is_plain(v) for k, v in value.items())
    if isinstance(value, list):
        return all(is_plain(v) for v in value)
    return value is None or type(value) in (str, int, float, bool)


# ------------------------------------------------------------------ data, not code


def test_a_checkpoint_holds_only_tensors_and_plain_data(written):
    checkpoint, _, _ = written
    data = checkpoint.data_path.read_bytes()
    payload = torch.load(io.BytesIO(data), weights_only=True)
    assert set(payload) == {"format", "write_id", "tensors"} and payload["format"] == FORMAT
    assert all(isinstance(t, torch.Tensor) for t in payload["tensors"].values())
    meta = json.loads(checkpoint.metadata_path.read_text())
    assert meta["format"] == FORMAT and is_plain(meta)
    assert b"lonlib" not in data and "lonlib" not in json.dumps(meta)  # no module is named


def test_a_restored_batch_continues_bit_for_bit(written):
    checkpoint, uninterrupted, original = written
    restored = load_inflight(checkpoint)
    assert restored.judge_batch == JUDGE_BATCH and restored.pending and not restored.busy.all()
    assert finish(restored) == uninterrupted
    # Every attribute of the batch and its parts is restored: an attribute added to the
    # trainer but not to its checkpoint makes the sets differ (bump FORMAT with the fix).
    for name in ("", "learner", "replay", "streams", "sim"):
        want = vars(original if not name else getattr(original, name))
        got = vars(restored if not name else getattr(restored, name))
        assert set(got) == set(want), name


# The checkpoint layout of FORMAT 3. Changing what lonlib.ddpg.checkpoint.to_checkpoint writes means
# checkpoints of running experiments stop being read: bump lonlib.experiment.checkpoints.FORMAT,
# then
# write the new layout here.
TENSORS = {
    "learner.actor": ("float32", 2),
    "learner.actor_exp_avg": ("float32", 2),
    "learner.actor_exp_avg_sq": ("float32", 2),
    "learner.actor_target": ("float32", 2),
    "learner.adam_steps": ("int64", 1),
    "learner.critic": ("float32", 2),
    "learner.critic_exp_avg": ("float32", 2),
    "learner.critic_exp_avg_sq": ("float32", 2),
    "learner.critic_target": ("float32", 2),
    "pending.omega": ("float32", 2),
    "pending.theta": ("float32", 2),
    "replay.position": ("int64", 1),
    "replay.rows": ("float32", 2),
    "replay.size": ("int64", 1),
    "searches.best_omega": ("float32", 2),
    "searches.best_theta": ("float32", 2),
    "searches.history": ("float64", 2),
    "searches.omega": ("float32", 2),
    "searches.theta": ("float32", 2),
    "sim.end_reason": ("int8", 1),
    "sim.phi": ("float64", 2),
    "sim.phi_dot": ("float64", 2),
    "sim.step_count": ("int64", 1),
    "sim.upright_all_sum": ("float64", 1),
    "sim.upright_mean_sum": ("float64", 1),
    "sim.upright_sum": ("float64", 1),
    "sim.x": ("float64", 2),
    "sim.x_dot": ("float64", 2),
    "slots.busy": ("bool", 1),
    "slots.dirty": ("bool", 1),
    "slots.episode_return": ("float64", 1),
    "slots.episodes": ("int64", 1),
    "slots.last_improvement": ("int64", 1),
    "slots.loss_count": ("int64", 1),
    "slots.loss_sum": ("float64", 2),
    "slots.obs": ("float32", 2),
    "slots.steps": ("int64", 1),
    "slots.updates": ("int64", 1),
}
METADATA = ["clock", "data", "format", "runs", "saved", "steps", "trainer", "trials", "write_id"]
TRAINER = [
    "ddpg",
    "env",
    "history_columns",
    "judge_batch",
    "pending",
    "searches",
    "sim_generator",
    "slots",
    "stream_seeds",
]
SEARCH = [
    "best",
    "env_steps",
    "episodes",
    "final_evaluation",
    "fitness",
    "pending",
    "seconds",
    "start_fitness",
    "started",
    "stop_reason",
    "tag",
    "updates",
]


def test_the_checkpoint_layout_is_the_one_of_its_format(written):
    checkpoint, _, _ = written
    tensors = torch.load(checkpoint.data_path, weights_only=True)["tensors"]
    meta = json.loads(checkpoint.metadata_path.read_text())
    search = next(s for s in meta["trainer"]["searches"] if s)
    layout = {name: (str(t.dtype).removeprefix("torch."), t.ndim) for name, t in tensors.items()}
    assert (FORMAT, layout, sorted(meta), sorted(meta["trainer"]), sorted(search)) == (
        3,
        TENSORS,
        METADATA,
        TRAINER,
        SEARCH,
    ), (
        "the checkpoint layout changed: bump lonlib.experiment.checkpoints.FORMAT and write it "
        "down here"
    )


# ------------------------------------------------------------------ hostile files refused


def rewrite(checkpoint, tensors=None, trainer=None, payload=None) -> None:
    """Replace what ``checkpoint``'s files hold (same names and write id): its data file by
    ``payload``, or by ``tensors`` in this format's envelope; its trainer's plain data."""
    if tensors is not None:
        payload = {"format": FORMAT, "write_id": checkpoint.write_id, "tensors": tensors}
    if payload is not None:
        torch.save(payload, checkpoint.data_path)
    if trainer is not None:
        meta = json.loads(checkpoint.metadata_path.read_text())
        meta["trainer"] = trainer
        checkpoint.metadata_path.write_text(json.dumps(meta))


@pytest.fixture
def copy_of(written, tmp_path):
    """A fresh copy of the written checkpoint, its tensors and its trainer's plain data."""
    checkpoint, _, _ = written
    folder = tmp_path / ".inflight"
    shutil.copytree(checkpoint.metadata_path.parent, folder)
    (copy,) = inflight_checkpoints(tmp_path)
    tensors = torch.load(copy.data_path, weights_only=True)["tensors"]
    meta = json.loads(copy.metadata_path.read_text())
    return copy, tensors, meta["trainer"]


def test_a_pickled_callable_is_refused_and_never_runs(copy_of, tmp_path):
    checkpoint, tensors, _ = copy_of
    marker = tmp_path / "planted-code-ran"
    rewrite(checkpoint, tensors={**tensors, "learner.actor": Planted(marker)})
    torch.load(checkpoint.data_path, weights_only=False)  # the payload is live...
    assert marker.exists()
    marker.unlink()
    with pytest.raises(ValueError, match="refused, not tensors.*io.open.*nothing in it was run"):
        load_inflight(checkpoint)  # ...and resuming does not run it
    assert not marker.exists()


def test_a_truncated_data_file_is_refused(copy_of):
    checkpoint, _, _ = copy_of
    data = checkpoint.data_path.read_bytes()
    for size in (0, 100, len(data) // 3, len(data) - 30):
        checkpoint.data_path.write_bytes(data[:size])
        with pytest.raises(ValueError, match="refused, not tensors and plain data"):
            load_inflight(checkpoint)


def test_a_truncated_metadata_file_is_refused(copy_of):
    checkpoint, _, _ = copy_of
    text = checkpoint.metadata_path.read_text()
    checkpoint.metadata_path.write_text(text[: len(text) - 40])
    with pytest.raises(ValueError, match="refused"):
        load_inflight(checkpoint)


def drop(mapping: dict, key: str) -> dict:
    return {k: v for k, v in mapping.items() if k != key}


def with_search(trainer: dict, **changes) -> dict:
    searches = list(trainer["searches"])
    slot = next(i for i, s in enumerate(searches) if s)
    searches[slot] = {**searches[slot], **changes}
    return {**trainer, "searches": searches}


def shaped(tensors: dict, name: str, value) -> dict:
    return {**tensors, name: value}


TENSOR_CASES = {
    "missing tensor": (lambda t: drop(t, "replay.rows"), "'replay.rows' is missing"),
    "extra tensor": (lambda t: shaped(t, "x", torch.zeros(1)), r"unexpected tensors \['x'\]"),
    "wrong shape": (
        lambda t: shaped(t, "learner.actor", t["learner.actor"][:, :-1]),
        "'learner.actor' is torch.float32 .*, expected torch.float32",
    ),
    "wrong dtype": (
        lambda t: shaped(t, "sim.x", t["sim.x"].float()),
        "'sim.x' is torch.float32 .*, expected torch.float64",
    ),
    "not a tensor": (lambda t: shaped(t, "slots.busy", [1, 2]), "'slots.busy' is not a dense"),
    "fill level past the buffer": (
        lambda t: shaped(t, "replay.size", t["replay.size"] + 10_000),
        "fill levels or positions outside the buffer",
    ),
    "a busy slot without a search": (
        lambda t: shaped(t, "slots.busy", torch.ones_like(t["slots.busy"])),
        "the busy slots are not the slots with a search",
    ),
    "a fraction in an episode count": (
        lambda t: shaped(t, "searches.history", t["searches.history"] + 0.5),
        "an integer column holds a fraction",
    ),
    "history of other length": (
        lambda t: shaped(t, "searches.history", t["searches.history"][:-1]),
        "'searches.history' is",
    ),
    # in-place updates of a Parameter, a tensor requiring a gradient or one whose elements
    # share memory fail (or write through) later
    "a Parameter": (
        lambda t: shaped(t, "slots.loss_sum", torch.nn.Parameter(t["slots.loss_sum"])),
        "'slots.loss_sum' is not a plain tensor",
    ),
    "a tensor requiring a gradient": (
        lambda t: shaped(t, "slots.loss_sum", t["slots.loss_sum"].clone().requires_grad_()),
        "'slots.loss_sum' is not a plain tensor",
    ),
    "elements sharing memory": (
        lambda t: shaped(t, "slots.loss_sum", torch.zeros(2, 1, dtype=torch.float64).expand(2, 3)),
        "'slots.loss_sum' is not a plain tensor",
    ),
    # NaN where the computation never makes one: it would crash later (or score NaN)
    "NaN in the simulator": (lambda t: nan_in(t, "sim.phi"), "'sim.phi' holds NaN"),
    "NaN in an Actor": (lambda t: nan_in(t, "learner.actor"), "'learner.actor' holds NaN"),
    "NaN in Adam's state": (
        lambda t: nan_in(t, "learner.critic_exp_avg"),
        "'learner.critic_exp_avg' holds NaN",
    ),
    "infinity in the replay buffer": (
        lambda t: nan_in(t, "replay.rows", np.inf),
        "'replay.rows' holds NaN or infinite",
    ),
    "NaN in an observation": (lambda t: nan_in(t, "slots.obs"), "'slots.obs' holds NaN"),
    "NaN in a start": (lambda t: nan_in(t, "searches.theta"), "'searches.theta' holds NaN"),
    "NaN in a queued policy": (lambda t: nan_in(t, "pending.omega"), "'pending.omega' holds"),
    "a negative second moment": (
        lambda t: shaped(t, "learner.actor_exp_avg_sq", -t["learner.actor_exp_avg_sq"] - 1),
        "negative Adam second moments",
    ),
}


def nan_in(tensors: dict, name: str, value: float = np.nan) -> dict:
    changed = tensors[name].clone()
    changed.view(-1)[-1] = value
    return shaped(tensors, name, changed)


@pytest.mark.parametrize("case", TENSOR_CASES)
def test_tensors_of_a_wrong_layout_are_refused(copy_of, case):
    checkpoint, tensors, _ = copy_of
    change, message = TENSOR_CASES[case]
    rewrite(checkpoint, tensors=change(tensors))
    with pytest.raises(ValueError, match=message):
        load_inflight(checkpoint)


PLAIN_CASES = {
    "missing key": (lambda p: drop(p, "stream_seeds"), r"missing keys \['stream_seeds'\]"),
    "slots as text": (lambda p: {**p, "slots": "3"}, "trainer.slots must be an integer"),
    "a search's steps as text": (
        lambda p: with_search(p, env_steps="70"),
        r"trainer.searches\[\d\].env_steps must be an integer",
    ),
    "a search's best as a number": (
        lambda p: with_search(p, best=0.5),
        r"trainer.searches\[\d\].best must be a list",
    ),
    "a tag as a mapping": (
        lambda p: with_search(p, tag={"p": 0.001}),
        r"trainer.searches\[\d\].tag must be plain data",
    ),
    "a queued evaluation of an empty slot": (
        lambda p: {**p, "pending": [[p["searches"].index(None), 0], *p["pending"][1:]]},
        "holds no search",
    ),
    "a queued count that is not the queue's": (
        lambda p: with_search(p, pending=99),
        "not its queued count",
    ),
    "a negative stream seed": (
        lambda p: {**p, "stream_seeds": [-1] * p["slots"]},
        "seed must be an integer in",
    ),
    "other DDPG settings keys": (
        lambda p: {**p, "ddpg": {**p["ddpg"], "surprise": 1}},
        r"unexpected keys \['surprise'\]",
    ),
    "invalid DDPG settings": (
        lambda p: {**p, "ddpg": {**p["ddpg"], "batch_size": -8}},
        "trainer.ddpg: batch_size must be",
    ),
    "a generator of another kind": (
        lambda p: {**p, "sim_generator": {"bit_generator": "MT19937"}},
        "state of a PCG64 generator",
    ),
    "episode records of other fields": (
        lambda p: {**p, "history_columns": p["history_columns"][:-1]},
        "trainer.history_columns",
    ),
    "not a mapping": (lambda p: [p], "trainer must be a mapping"),
}


@pytest.mark.parametrize("case", PLAIN_CASES)
def test_plain_data_of_a_wrong_layout_is_refused(copy_of, case):
    checkpoint, _, plain = copy_of
    change, message = PLAIN_CASES[case]
    rewrite(checkpoint, trainer=change(plain))
    with pytest.raises(ValueError, match=message):
        load_inflight(checkpoint)


def test_a_data_file_whose_format_is_a_tensor_is_refused(copy_of):
    checkpoint, tensors, _ = copy_of
    rewrite(
        checkpoint,
        payload={
            "format": torch.tensor([3, 3]),
            "write_id": checkpoint.write_id,
            "tensors": tensors,
        },
    )
    with pytest.raises(ValueError, match="not the data file its metadata describes"):
        load_inflight(checkpoint)


PLANTED_TENSORS = {
    "a tensor as the format": lambda c, t: rewrite(
        c, payload={"format": torch.tensor([FORMAT] * 2), "write_id": c.write_id, "tensors": t}
    ),
    "a Parameter": lambda c, t: rewrite(c, tensors=TENSOR_CASES["a Parameter"][0](t)),
    "NaN in the simulator": lambda c, t: rewrite(c, tensors=nan_in(t, "sim.phi")),
}


@pytest.mark.parametrize("case", PLANTED_TENSORS)
def test_planted_tensors_are_refused_by_a_resuming_experiment(
    serial, tmp_path, small_killed, monkeypatch, caplog, case
):
    def plant(checkpoint):
        tensors = torch.load(checkpoint.data_path, weights_only=True)["tensors"]
        PLANTED_TENSORS[case](checkpoint, tensors)

    log = resumed_despite(serial, tmp_path, small_killed, monkeypatch, caplog, plant)
    assert "stale in-flight checkpoint removed" in log and "refused" in log


def test_a_data_file_of_another_write_is_refused(copy_of):
    checkpoint, tensors, _ = copy_of
    rewrite(checkpoint, payload={"format": FORMAT, "write_id": "other", "tensors": tensors})
    with pytest.raises(ValueError, match="not the data file its metadata describes"):
        load_inflight(checkpoint)


def test_metadata_naming_another_data_file_is_not_listed(copy_of, tmp_path, caplog):
    checkpoint, _, _ = copy_of
    meta = json.loads(checkpoint.metadata_path.read_text())
    meta["data"] = "../../elsewhere.pt"
    checkpoint.metadata_path.write_text(json.dumps(meta))
    assert inflight_checkpoints(tmp_path) == []
    assert "its data file must be" in caplog.text


def test_a_planted_checkpoint_is_refused_by_a_resuming_experiment(
    serial, tmp_path, small_killed, monkeypatch, caplog
):
    """The whole resume path: a checkpoint of this format whose data file carries a
    callable is reported and removed; its runs continue from their stored trials."""
    small_killed(tmp_path)
    (checkpoint,) = inflight_checkpoints(tmp_path)
    tensors = torch.load(checkpoint.data_path, weights_only=True)["tensors"]
    marker = tmp_path / "planted-code-ran"
    rewrite(checkpoint, tensors={**tensors, "replay.rows": Planted(marker)})
    with caplog.at_level("INFO", logger="lonlib"):
        run_experiment(SMALL, tmp_path, progress=False, executor="lockstep", slots=2)
    assert not marker.exists()
    assert "stale in-flight checkpoint removed" in caplog.text and "io.open" in caplog.text
    assert "resumed" not in caplog.text
    want = serial[0][(serial[0]["p"] == P) & (serial[0]["run"] < 2)].reset_index(drop=True)
    pd.testing.assert_frame_equal(stored(tmp_path)[0], want)
    assert not list((tmp_path / ".inflight").iterdir())


# ------------------------------------------------------------------ crafted metadata

DEEP = "[" * 100_000 + "]" * 100_000  # nested past any parser's recursion limit
HUGE = 10**400  # an integer too large for a float


def with_metadata(checkpoint, change) -> None:
    """Rewrite ``checkpoint``'s metadata: ``change(meta)`` is the new mapping or text."""
    meta = change(json.loads(checkpoint.metadata_path.read_text()))
    checkpoint.metadata_path.write_text(meta if isinstance(meta, str) else json.dumps(meta))


def with_search_value(meta: dict, **changes) -> dict:
    return {**meta, "trainer": with_search(meta["trainer"], **changes)}


JSON_CASES = {
    "a huge p": (lambda m: {**m, "runs": [[HUGE, 0], *m["runs"][1:]]}, r"runs\[0\] p is too large"),
    "a huge saved": (lambda m: {**m, "saved": HUGE}, "saved is too large for a float"),
    "a huge clock": (lambda m: {**m, "clock": HUGE}, "clock is too large for a float"),
    "a huge start time": (lambda m: with_search_value(m, started=HUGE), "started is too large"),
    "a huge fitness": (lambda m: with_search_value(m, fitness=HUGE), "fitness is too large"),
    "huge seconds": (lambda m: with_search_value(m, seconds=HUGE), "seconds is too large"),
    "a huge best": (lambda m: with_search_value(m, best=[HUGE, 0.0]), "best is too large"),
    "deep nesting": (lambda m: DEEP, "maximum recursion depth"),
    "deep nesting inside": (
        lambda m: json.dumps({**m, "trainer": 0}).replace('"trainer": 0', f'"trainer": {DEEP}'),
        "maximum recursion depth",
    ),
}


@pytest.mark.parametrize("case", JSON_CASES)
def test_crafted_metadata_is_refused_not_raised(copy_of, tmp_path, caplog, case):
    """Numbers too large for a float and nesting past the parser's limit: refused with a
    reason, when listed (every executor and ``lonlib status`` list checkpoints) or read."""
    checkpoint, _, _ = copy_of
    change, message = JSON_CASES[case]
    with_metadata(checkpoint, change)
    listed = inflight_checkpoints(tmp_path)
    if listed:
        with pytest.raises(ValueError, match=f"refused, .*{message}"):
            load_inflight(*listed)
    else:
        assert re.search(f"refused in-flight checkpoint skipped .*{message}", caplog.text)


@pytest.mark.parametrize("case", ["a huge p", "a huge start time", "deep nesting"])
def test_crafted_metadata_is_refused_by_a_resuming_experiment(
    serial, tmp_path, small_killed, monkeypatch, caplog, case
):
    change, message = JSON_CASES[case]
    log = resumed_despite(
        serial, tmp_path, small_killed, monkeypatch, caplog, lambda c: with_metadata(c, change)
    )
    assert re.search(f"in-flight checkpoint removed .*{message}", log)


def resumed_despite(serial, tmp_path, small_killed, monkeypatch, caplog, plant) -> str:
    """A lockstep experiment killed mid-search, its checkpoint changed by ``plant``, then
    resumed: it is refused (no traceback) and removed, the runs continue from their stored
    trials to the uninterrupted results and nothing is created outside the experiment's
    runs. The log."""
    small_killed(tmp_path)
    (checkpoint,) = inflight_checkpoints(tmp_path)
    plant(checkpoint)
    with caplog.at_level("INFO", logger="lonlib"):
        run_status(tmp_path)  # `lonlib status` lists the checkpoints too
        run_experiment(SMALL, tmp_path, progress=False, executor="lockstep", slots=2)
    assert "resumed" not in caplog.text and "Traceback" not in caplog.text
    want = serial[0][(serial[0]["p"] == P) & (serial[0]["run"] < 2)].reset_index(drop=True)
    pd.testing.assert_frame_equal(stored(tmp_path)[0], want)
    assert not list((tmp_path / ".inflight").iterdir())
    folders = sorted(str(path.relative_to(tmp_path)) for path in tmp_path.glob("p=*/*"))
    assert folders == ["p=0.001/run_0000", "p=0.001/run_0001"]
    return caplog.text


# ------------------------------------------------------------------ the runs it lists

PLAN = ({P}, 3)  # the runs of an experiment of one p and three runs
RUN_CASES = {  # the metadata's runs, or a search's tag: refused when listed, or when read
    "p NaN": (lambda m: {**m, "runs": [[np.nan, 0], m["runs"][1]]}, r"runs\[0\] p must be finite"),
    "p of another experiment": (
        lambda m: {**m, "runs": [[0.5, 0], m["runs"][1]]},
        "run 0 of p=0.5 is not one of this experiment's",
    ),
    "a negative run": (lambda m: {**m, "runs": [[P, -3], m["runs"][1]]}, r"run must be in \[0"),
    "a run past the experiment's": (
        lambda m: {**m, "runs": [m["runs"][0], [P, 7]]},
        "run 7 of p=0.001 is not one of this experiment's",
    ),
    "a run as a fraction": (
        lambda m: {**m, "runs": [[P, 0.5], m["runs"][1]]},
        "must be an integer",
    ),
    "a run listed twice": (lambda m: {**m, "runs": [m["runs"][0]] * 2}, "listed twice"),
    "negative trials": (lambda m: {**m, "trials": [-1, 0]}, r"trials must be in \[0"),
    "negative steps": (lambda m: {**m, "steps": [-1, 125]}, r"steps must be in \[0"),
    "a slot's run not listed": (
        lambda m: {**m, "runs": [m["runs"][0], [P, 1]]},
        "busy slots' searches are not the runs its metadata lists",
    ),
    "a slot's tag not a run": (
        lambda m: with_search_value(m, tag="planted"),
        "busy slots' searches are not the runs its metadata lists",
    ),
    "other env steps": (
        lambda m: {**m, "steps": [m["steps"][0], 7]},
        "env steps are not those its metadata lists",
    ),
}


@pytest.mark.parametrize("case", RUN_CASES)
def test_runs_that_are_not_the_experiments_or_the_batchs_are_refused(
    copy_of, tmp_path, caplog, case
):
    checkpoint, _, _ = copy_of
    change, message = RUN_CASES[case]
    with_metadata(checkpoint, change)
    listed = inflight_checkpoints(tmp_path, PLAN)
    if listed:
        with pytest.raises(ValueError, match=f"refused, .*{message}"):
            load_inflight(*listed)
    else:
        assert re.search(f"refused in-flight checkpoint skipped .*{message}", caplog.text)


def test_a_run_of_an_earlier_sessions_configuration_is_the_experiments(tmp_path):
    """A session may run fewer p values or runs than the experiment's manifest holds."""
    config = SMALL
    run_experiment(dataclasses.replace(config, max_local_searches=1), tmp_path, progress=False)
    fewer = dataclasses.replace(config, runs=1, perturbations=(1e-4,))
    perturbations, runs = experiment_plan(tmp_path, fewer)
    assert (set(perturbations), runs) == ({1e-4, P}, 2)


PLANTED_RUNS = {
    "p NaN": lambda m: {**m, "runs": [[np.nan, 0], m["runs"][1]]},
    "a run past the experiment's": lambda m: {**m, "runs": [m["runs"][0], [P, 7]]},
    "a negative run": lambda m: {**m, "runs": [[P, -3], m["runs"][1]]},
    "a slot's tag not listed": lambda m: with_search_value(m, tag=[P, 5]),
}


@pytest.mark.parametrize("case", PLANTED_RUNS)
def test_runs_that_are_not_the_experiments_are_refused_by_a_resuming_experiment(
    serial, tmp_path, small_killed, monkeypatch, caplog, case
):
    """Nothing is locked or created for a run that is not the experiment's (no p=nan/,
    run_-003/ or run_0007/), and a slot training a run its metadata does not list is
    refused, not resumed to a KeyError."""
    plant = PLANTED_RUNS[case]
    log = resumed_despite(
        serial, tmp_path, small_killed, monkeypatch, caplog, lambda c: with_metadata(c, plant)
    )
    assert "in-flight checkpoint removed" in log and "refused" in log


# ------------------------------------------------------------------ counters out of range


def with_tensor(name: str, change):
    """A tensor case: ``name`` replaced by ``change(tensor)``."""
    return lambda t: shaped(t, name, change(t[name].clone()))


def set_first(tensor, value):
    tensor.view(-1)[0] = value
    return tensor


COUNTER_CASES = {
    "negative steps": (with_tensor("slots.steps", lambda t: -t), r"slots.steps: slot 0"),
    "steps past the budget": (
        with_tensor("slots.steps", lambda t: t + CONFIG.ddpg.max_steps),
        r"slots.steps: slot 0",
    ),
    "negative episodes": (with_tensor("slots.episodes", lambda t: -t), "slots.episodes: slot 0"),
    "negative updates": (with_tensor("slots.updates", lambda t: -t), "slots.updates: slot 0"),
    "more updates than steps": (
        with_tensor("slots.updates", lambda t: t + 1000),
        "slots.updates: slot 0",
    ),
    "negative loss count": (
        with_tensor("slots.loss_count", lambda t: t - 100),
        "slots.loss_count: slot 0",
    ),
    "negative last improvement": (
        with_tensor("slots.last_improvement", lambda t: -t),
        "slots.last_improvement: slot 0",
    ),
    "negative episode steps": (
        with_tensor("sim.step_count", lambda t: set_first(t, -1)),
        "sim.step_count: slot 0",
    ),
    "episode steps past the limit": (
        with_tensor("sim.step_count", lambda t: set_first(t, CONFIG.env.steps + 1)),
        "sim.step_count: slot 0",
    ),
    "an end reason that is none": (
        with_tensor("sim.end_reason", lambda t: set_first(t, 77)),
        "sim.end_reason: slot 0",
    ),
    "a busy slot's episode ended": (
        with_tensor("sim.end_reason", lambda t: set_first(t, 2)),
        "sim.end_reason: slot 0",
    ),
    "more upright steps than steps": (
        with_tensor("sim.upright_sum", lambda t: t + 1000),
        "sim.upright_sum: slot 0",
    ),
    "a negative episode in the history": (
        with_tensor("searches.history", lambda t: set_first(t, -1)),
        "searches.history: a negative count",
    ),
}


@pytest.mark.parametrize("case", COUNTER_CASES)
def test_counters_no_search_reaches_are_refused(copy_of, case):
    checkpoint, tensors, _ = copy_of
    change, message = COUNTER_CASES[case]
    rewrite(checkpoint, tensors=change(tensors))
    with pytest.raises(ValueError, match=f"refused, .*{message}"):
        load_inflight(checkpoint)


PLAIN_COUNTER_CASES = {
    "judge batch of a billion": (
        lambda p: {**p, "judge_batch": 10**9},
        r"judge_batch must be in \[1, 16\]",
    ),
    "judge batch zero": (lambda p: {**p, "judge_batch": 0}, r"judge_batch must be in \[1, 16\]"),
    "fewer than queued": (lambda p: {**p, "judge_batch": 1}, "more queued than a step leaves"),
    "a search's env steps past the budget": (
        lambda p: with_search(p, env_steps=10**12),
        r"env_steps must be in \[0, 240\]",
    ),
    "a search's negative env steps": (
        lambda p: with_search(p, env_steps=-5),
        r"env_steps must be in \[0, 240\]",
    ),
    "a search's updates past the budget": (
        lambda p: with_search(p, updates=10**9),
        r"updates must be in \[0, 240\]",
    ),
    "a search's infinite start time": (
        lambda p: with_search(p, started=np.inf),
        "started must be finite",
    ),
    "a search's negative seconds": (lambda p: with_search(p, seconds=-1.0), "seconds must be >= 0"),
    "a search's NaN fitness": (
        lambda p: with_search(p, fitness=np.nan),
        "fitness must be a number",
    ),
    "a search's stop reason": (lambda p: with_search(p, stop_reason="x"), "stop_reason must be"),
    "a search's episodes not its slot's": (
        lambda p: with_search(p, episodes=0, pending=0),
        "trainer.searches: slot 0",
    ),
}


@pytest.mark.parametrize("case", PLAIN_COUNTER_CASES)
def test_plain_counters_no_search_reaches_are_refused(copy_of, case):
    checkpoint, tensors, plain = copy_of
    change, message = PLAIN_COUNTER_CASES[case]
    changed = change(plain)
    if case == "a search's episodes not its slot's":  # its history and queue go with it
        tensors = {**tensors, "searches.history": tensors["searches.history"][3:]}
        tensors["pending.theta"] = tensors["pending.theta"][:0]
        tensors["pending.omega"] = tensors["pending.omega"][:0]
        changed = {**changed, "pending": []}
        changed["searches"][2] = {**changed["searches"][2], "pending": 0}
        rewrite(checkpoint, tensors=tensors)
    rewrite(checkpoint, trainer=changed)
    with pytest.raises(ValueError, match=f"refused, .*{message}"):
        load_inflight(checkpoint)


@pytest.mark.parametrize(
    "case", ["negative steps", "a busy slot's episode ended", "episode steps past the limit"]
)
def test_counters_no_search_reaches_are_refused_by_a_resuming_experiment(
    serial, tmp_path, small_killed, monkeypatch, caplog, case
):
    def plant(checkpoint):
        tensors = torch.load(checkpoint.data_path, weights_only=True)["tensors"]
        rewrite(checkpoint, tensors=COUNTER_CASES[case][0](tensors))

    log = resumed_despite(serial, tmp_path, small_killed, monkeypatch, caplog, plant)
    assert "stale in-flight checkpoint removed" in log and "no search reaches" in log


def test_every_checkpoint_a_batch_writes_is_read_back(tmp_path, monkeypatch):
    """The ranges refused above are the step loop's invariants: every state a batch writes
    (searches starting, in their warm-up, training, ending, slots refilled or freed, the
    start a candidate, ties broken) is read back."""
    import lonlib.experiment.lockstep

    ddpg = dataclasses.replace(CONFIG.ddpg, count_start=True, plateau_tiebreak=True)
    config = dataclasses.replace(CONFIG, runs=3, max_local_searches=2, ddpg=ddpg)
    read = []

    def read_back(_path, trainer, _trials):  # what save_inflight writes, read as it is read
        busy = [slot for slot in range(trainer.slots) if trainer.busy[slot]]
        plain, tensors = to_checkpoint(trainer)
        plain = json.loads(json.dumps(plain))
        runs, steps = [trainer.tags()[s] for s in busy], [int(trainer.steps[s]) for s in busy]
        stored = StoredBatch(Path("x.pt"), plain, tensors, 0.0, tuple(runs), tuple(steps))
        read.append(stored.trainer().slots)

    monkeypatch.setattr(lonlib.experiment.lockstep, "save_inflight", read_back)
    run_experiment(
        config, tmp_path, progress=False, executor="lockstep", slots=4, checkpoint_seconds=0
    )
    assert len(read) > 500


# ------------------------------------------------------------------ names


def renamed(checkpoint, name: str, write_id: str | None = None) -> Path:
    """``checkpoint`` moved to the batch id ``name`` (and write id): its metadata path."""
    folder, write_id = checkpoint.metadata_path.parent, write_id or checkpoint.write_id
    meta = json.loads(checkpoint.metadata_path.read_text())
    meta |= {"write_id": write_id, "data": f"{name}.{write_id}.pt"}
    checkpoint.metadata_path.unlink()
    checkpoint.data_path.rename(folder / f"{name}.{write_id}.pt")
    (folder / f"{name}.json").write_text(json.dumps(meta))
    return folder / f"{name}.json"


@pytest.mark.parametrize("name", ["*", "[0-9a-f]*", "0123456789AB"])
def test_a_checkpoint_of_another_name_is_ignored_and_never_a_pattern(
    copy_of, tmp_path, caplog, name
):
    checkpoint, _, _ = copy_of
    folder = checkpoint.metadata_path.parent
    meta = renamed(checkpoint, name)
    others = [folder / "0123456789ab.0123456789ab.pt", folder / ".0123456789ab.json.x.tmp"]
    for other in others:  # another batch's data file, and its write in progress
        other.write_bytes(b"theirs")
    assert inflight_checkpoints(tmp_path) == []
    remove_leftovers(meta)
    remove_inflight(meta)
    assert all(other.exists() for other in others)
    assert "not the name of an in-flight checkpoint" in caplog.text


def test_a_write_id_that_is_a_path_is_refused(copy_of, tmp_path, caplog):
    checkpoint, _, _ = copy_of
    (checkpoint.metadata_path.parent / f"{checkpoint.name}.x").mkdir()
    (tmp_path / "elsewhere").mkdir()  # the data file it names: outside the folder
    renamed(checkpoint, checkpoint.name, write_id="x/../../elsewhere/y")
    assert (tmp_path / "elsewhere" / "y.pt").exists()
    assert inflight_checkpoints(tmp_path) == []
    assert "write_id must be 12 hex digits" in caplog.text


def test_a_checkpoint_named_as_a_pattern_is_ignored_by_a_resuming_experiment(
    serial, tmp_path, small_killed, monkeypatch, caplog
):
    """A metadata file named ``*.json`` is never read, nor its name used to find the files
    of its batch: another batch's files stay; its runs continue from their stored trials."""
    small_killed(tmp_path)
    (checkpoint,) = inflight_checkpoints(tmp_path)
    folder = checkpoint.metadata_path.parent
    other = folder / "0123456789ab.0123456789ab.pt"  # another batch's
    other.write_bytes(b"theirs")
    planted = renamed(checkpoint, "*")
    with caplog.at_level("INFO", logger="lonlib"):
        run_experiment(SMALL, tmp_path, progress=False, executor="lockstep", slots=2)
    assert other.exists() and planted.exists()
    assert "not the name of an in-flight checkpoint" in caplog.text
    assert "resumed" not in caplog.text and "Traceback" not in caplog.text
    want = serial[0][(serial[0]["p"] == P) & (serial[0]["run"] < 2)].reset_index(drop=True)
    pd.testing.assert_frame_equal(stored(tmp_path)[0], want)


# ------------------------------------------------------------------ other settings

SETTINGS_CASES = {
    "threads": ({"ddpg": {"threads": 2}}, "threads=2 (this session: 1)"),
    "device": ({"ddpg": {"device": "cuda"}}, "device='cuda' (this session: 'cpu')"),
    "two DDPG settings": (
        {"ddpg": {"learning_rate": 0.01, "threads": 3}},
        "learning_rate=0.01 (this session: 0.001), threads=3 (this session: 1)",
    ),
    "an environment setting": ({"env": {"steps": 41}}, "env.steps=41 (this session: 40)"),
}


@pytest.mark.parametrize("case", SETTINGS_CASES)
def test_a_checkpoint_of_other_settings_names_those_that_differ(copy_of, case):
    checkpoint, _, plain = copy_of
    changes, differ = SETTINGS_CASES[case]
    rewrite(checkpoint, trainer={**plain, **{k: {**plain[k], **v} for k, v in changes.items()}})
    with pytest.raises(OtherSettings) as raised:
        check_settings(checkpoint, read_inflight(checkpoint), CONFIG.env, CONFIG.ddpg)
    assert f"in-flight checkpoint trained with {differ}: resume with those" in str(raised.value)
    with pytest.raises(OtherSettings, match=re.escape(differ)):  # nor split with them
        split_inflight(checkpoint, 2, (CONFIG.env, CONFIG.ddpg))
    assert inflight_checkpoints(checkpoint.metadata_path.parent.parent) == [checkpoint]


def test_a_checkpoint_of_other_settings_is_kept_by_resuming_processes(
    serial, tmp_path, small_killed, monkeypatch, caplog, capfd
):
    """Processes resuming a checkpoint split it only if it was trained with their settings:
    built with its own it would set this process's torch threads (and split a batch that
    none of them continues)."""
    small_killed(tmp_path)
    (checkpoint,) = inflight_checkpoints(tmp_path)
    trainer = load_inflight(checkpoint)
    trainer.hp = dataclasses.replace(trainer.hp, threads=2)
    save_inflight(checkpoint.metadata_path, trainer, dict.fromkeys(checkpoint.runs, 0))
    threads = torch.get_num_threads()
    with caplog.at_level("INFO", logger="lonlib"):
        run_experiment(SMALL, tmp_path, progress=False, executor="lockstep", slots=2, workers=2)
    assert torch.get_num_threads() == threads
    assert "trained with threads=2 (this session: 1): resume with those" in caplog.text
    assert "resumed" not in caplog.text + capfd.readouterr().err
    want = serial[0][(serial[0]["p"] == P) & (serial[0]["run"] < 2)].reset_index(drop=True)
    pd.testing.assert_frame_equal(stored(tmp_path)[0], want)
    assert not inflight_checkpoints(tmp_path)  # its runs ended: removed


# ------------------------------------------------------------------ a format version


@pytest.mark.parametrize("version", [2, 4])
def test_a_checkpoint_of_another_format_is_refused_saying_what_to_do(
    serial, tmp_path, small_killed, monkeypatch, caplog, version
):
    """Format 2 is what lonlib wrote before: a pickle of the trainer. Planted as one (its
    data file a callable), it is never read; the experiment ends as an uninterrupted one."""
    small_killed(tmp_path)
    (checkpoint,) = inflight_checkpoints(tmp_path)
    marker = tmp_path / "planted-code-ran"
    payload = {"format": version, "layout": "a20ab573a108", "write_id": checkpoint.write_id}
    rewrite(checkpoint, payload={**payload, "clock": 0.0, "trainer": Planted(marker)})
    meta = json.loads(checkpoint.metadata_path.read_text())
    meta = {key: meta[key] for key in ("write_id", "data", "saved", "runs", "trials", "steps")}
    checkpoint.metadata_path.write_text(json.dumps({**meta, "format": version}))
    with caplog.at_level("INFO", logger="lonlib"):
        run_experiment(SMALL, tmp_path, progress=False, executor="lockstep", slots=2)
    assert not marker.exists()
    (message,) = [r.getMessage() for r in caplog.records if "of format" in r.getMessage()]
    assert f"in-flight checkpoint of format {version}" in message
    assert "continue from their stored trials, losing at most the minutes" in message
    assert "Delete" in message and "silence" in message
    assert "resumed" not in caplog.text and "Traceback" not in caplog.text
    want = serial[0][(serial[0]["p"] == P) & (serial[0]["run"] < 2)].reset_index(drop=True)
    pd.testing.assert_frame_equal(stored(tmp_path)[0], want)
    assert checkpoint.metadata_path.exists()  # left for the user to delete


# ------------------------------------------------------------------ no module paths


MOVED = """
import json, sys
from lonlib.experiment.checkpoints import load_inflight
from lonlib.storage.inflight import inflight_checkpoints
import lonlib
assert lonlib.__file__.startswith(sys.argv[2]), lonlib.__file__
assert "lonlib.ddpg.trainer" not in sys.modules and "lonlib.trainers_moved" in sys.modules
(checkpoint,) = inflight_checkpoints(sys.argv[1])
trainer = load_inflight(checkpoint)
assert type(trainer).__name__ == "RenamedTrainer"
ended = {}
while trainer.busy.any():
    for tag, result in trainer.step():
        ended[str(tag)] = {"fitness": result.fitness, "env_steps": result.env_steps,
                           "theta": result.theta.tobytes().hex()}
print(json.dumps(ended))
"""


def test_a_checkpoint_resumes_in_a_package_whose_trainer_moved_and_was_renamed(written, tmp_path):
    """The checkpoint names no module or class: a copy of lonlib with the trainer's module
    renamed (lonlib.ddpg.trainer -> lonlib.trainers_moved) and its class too (SlotTrainer ->
    RenamedTrainer) resumes it, in a process that never imports the original package."""
    checkpoint, uninterrupted, _ = written
    package = Path(lonlib.__file__).parent
    copy = tmp_path / "moved" / "lonlib"
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "ddpg" / "trainer.py").rename(copy / "trainers_moved.py")
    for path in copy.rglob("*.py"):
        text = re.sub(r"\blonlib\.ddpg\.trainer\b", "lonlib.trainers_moved", path.read_text())
        path.write_text(text.replace("SlotTrainer", "RenamedTrainer"))
    script = tmp_path / "resume.py"
    script.write_text(MOVED)
    env = {**os.environ, "PYTHONPATH": str(copy.parent)}
    folder = checkpoint.metadata_path.parent.parent
    done = subprocess.run(
        [sys.executable, str(script), str(folder), str(copy)],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout)
    want = {
        str(tag): {
            "fitness": r["fitness"],
            "env_steps": r["env_steps"],
            "theta": r["theta"].hex(),
        }
        for tag, r in uninterrupted.items()
    }
    assert got == want
