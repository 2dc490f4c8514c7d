"""The lockstep executor: the same trials as the serial executor, whatever the batch."""

import copy
import dataclasses
import hashlib
import shutil

import numpy as np
import pandas as pd
import pytest

from lonlib.config import ExperimentConfig, PendulumConfig
from lonlib.experiment.running import run_experiment, run_one, status
from lonlib.storage.status import run_status
from lonlib.storage.trials import read_experiment_trials
from tests.conftest import built_once, tiny_ddpg

# Searches stop by patience at different times, so slots are refilled while others are in
# their warm-up or training: a run's trials must still not depend on its neighbours.
CONFIG = ExperimentConfig(
    name="lockstep",
    perturbations=(1e-3, 1e-4),
    runs=4,
    tolerance=2,
    max_local_searches=4,
    env=PendulumConfig(
        n_carts=1,
        steps=40,
        upright_angle=2.9,
        motor="acceleration",
        motor_gain=2.0,
        initial_noise=0.02,  # refills draw start noise from the new search's streams
    ),
    ddpg=tiny_ddpg(max_steps=240, patience_steps=60),
)
TIME_COLUMNS = ["seconds"]


def stored(folder):
    """Trials (without timings) and a digest of every stored optimum and history."""
    trials = read_experiment_trials(folder).drop(columns=TIME_COLUMNS)
    digest = {}
    for path in sorted(folder.glob("p=*/run_*/*")):
        if path.suffix == ".npz":
            with np.load(path) as data:
                digest[str(path.relative_to(folder))] = hashlib.sha256(
                    b"".join(data[k].tobytes() for k in sorted(data.files))
                ).hexdigest()
        elif path.name.startswith("history_"):
            history = pd.read_parquet(path).drop(columns=["seconds"])
            digest[str(path.relative_to(folder))] = history
    return trials, digest


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """CONFIG run by the serial executor (once per session: test_inflight.py beside this file
    and each xdist worker share it), as :func:`stored` reads it."""
    folder = built_once(
        tmp_path_factory,
        "lockstep-serial",
        lambda folder: run_experiment(CONFIG, folder, progress=False, executor="serial"),
    )
    return stored(folder)


@pytest.fixture(scope="module")
def serial_two_runs(tmp_path_factory):
    """The serial executor's runs 0 and 1 of each p of CONFIG (a run's trials are its own:
    the same in an experiment of fewer runs), as :func:`stored` reads them."""
    folder = tmp_path_factory.mktemp("serial-two-runs")
    two_runs = dataclasses.replace(CONFIG, runs=2)
    run_experiment(two_runs, folder, progress=False, executor="serial")
    return stored(folder)


@pytest.mark.parametrize("slots", [3, 8])  # one slot: the resume test below
def test_lockstep_trials_equal_the_serial_executors_bit_for_bit(
    serial, tmp_path, slots, device_mode
):
    # "cpu as device": the batch takes a CUDA device's paths, the serial runs the CPU's
    run_experiment(CONFIG, tmp_path, progress=False, executor="lockstep", slots=slots)
    trials, digest = stored(tmp_path)
    want_trials, want_digest = serial
    assert len(trials) > 2 * CONFIG.runs  # runs went past their first search
    assert trials["stop_reason"].eq("patience").any()  # searches ended at different times
    pd.testing.assert_frame_equal(trials, want_trials)
    assert digest.keys() == want_digest.keys()
    for key, value in digest.items():
        if isinstance(value, pd.DataFrame):
            pd.testing.assert_frame_equal(value, want_digest[key], check_exact=True)
        else:
            assert value == want_digest[key], key


def test_a_killed_lockstep_experiment_resumes_to_the_same_trials(serial, tmp_path, monkeypatch):
    import lonlib.experiment.lockstep

    stored_steps = []
    save = lonlib.experiment.lockstep.save_step

    def save_then_die(*args, **kwargs):
        save(*args, **kwargs)
        stored_steps.append(args[1:3])
        if len(stored_steps) == 5:
            raise KeyboardInterrupt  # killed with searches of other runs in flight

    monkeypatch.setattr(lonlib.experiment.lockstep, "save_step", save_then_die)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(CONFIG, tmp_path, progress=False, executor="lockstep", slots=4)
    monkeypatch.undo()
    assert len(read_experiment_trials(tmp_path)) == 5
    # every run's lock was released: a second session resumes at once, with other slots
    run_experiment(CONFIG, tmp_path, progress=False, executor="lockstep", slots=1)
    trials, digest = stored(tmp_path)
    pd.testing.assert_frame_equal(trials, serial[0])
    assert digest.keys() == serial[1].keys()


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"executor": "lockstep", "scheduler": "dask-local"}, "does not use one"),
        ({"executor": "dask"}, "needs a scheduler"),
        ({"executor": "threads"}, "executor must be one of"),
        ({"executor": "lockstep", "slots": 0}, "slots must be"),
        ({"executor": "lockstep", "slots": 2, "config": {"batch_size": 36}}, "multiple of 8"),
        ({"executor": "lockstep", "config": {"update": "autograd"}}, "update='lean'"),
    ],
)
def test_bad_executor_settings_are_refused_before_any_compute(tmp_path, changes, message):
    changes = dict(changes)
    ddpg = dataclasses.replace(CONFIG.ddpg, **changes.pop("config", {}))
    config = dataclasses.replace(CONFIG, ddpg=ddpg)
    with pytest.raises(ValueError, match=message):
        run_experiment(config, tmp_path / "out", progress=False, **changes)
    assert not (tmp_path / "out").exists()


def test_executor_and_slots_are_not_part_of_what_must_match_to_resume(tmp_path):
    config = dataclasses.replace(CONFIG, runs=1, perturbations=(1e-3,), max_local_searches=1)
    run_experiment(config, tmp_path, progress=False, executor="serial")
    lockstep = dataclasses.replace(config, executor="lockstep", slots=2, runs=2)
    trials = run_experiment(lockstep, tmp_path, progress=False)
    assert sorted(trials["run"].unique()) == [0, 1]


def test_cli_runs_the_lockstep_executor(tmp_path, capsys):
    from lonlib.cli import main

    path = tmp_path / "tiny.yaml"
    path.write_text(
        "name: tiny\nperturbations: [1.0e-3]\nruns: 2\ntolerance: 1\nmax_local_searches: 2\n"
        "env: {n_carts: 1, steps: 40}\n"
        "ddpg: {batch_size: 16, buffer_size: 200, warmup_steps: 30, max_steps: 60, min_steps: 0}\n"
    )
    main(
        [
            "run",
            str(path),
            "--executor",
            "lockstep",
            "--slots",
            "2",
            "--device",
            "cpu",
            "--out",
            str(tmp_path / "out"),
            "--quiet",
        ]
    )
    assert "local searches stored" in capsys.readouterr().out
    assert len(read_experiment_trials(tmp_path / "out")) >= 2


def test_lockstep_in_two_processes_gives_the_serial_trials(serial, tmp_path, monkeypatch, capfd):
    from lonlib.storage.inflight import inflight_checkpoints

    # Killed in one process, resumed in two: its checkpoint is split, one part per process.
    killed_after_checkpoints(monkeypatch, tmp_path, CONFIG, slots=4, writes=100)
    capfd.readouterr()
    run_experiment(CONFIG, tmp_path, progress=False, executor="lockstep", slots=3, workers=2)
    assert capfd.readouterr().err.count("resumed 2 searches in flight (200 env steps)") == 2
    assert not inflight_checkpoints(tmp_path)
    trials, digest = stored(tmp_path)
    pd.testing.assert_frame_equal(trials, serial[0])
    assert digest.keys() == serial[1].keys()


@pytest.mark.serial  # its processes' timing decides what is in flight when they yield
def test_processes_are_dealt_out_again_when_one_runs_out_of_runs(
    serial_two_runs, tmp_path, caplog, capfd
):
    from lonlib.experiment.lockstep_workers import run_lockstep_processes
    from lonlib.storage.inflight import inflight_checkpoints

    # The second process's one run has ended already, so it is idle at once while the first
    # trains a batch of two searches: the first stops after writing its checkpoint, which a
    # second round splits, one search per process.
    p, q = CONFIG.perturbations
    run_one(tmp_path, CONFIG, p, 1)
    jobs = [(p, 0), (p, 1), (q, 0)]
    summaries = []
    with caplog.at_level("INFO", logger="lonlib"):
        run_lockstep_processes(
            tmp_path, CONFIG, jobs, summaries.append, slots=2, workers=2, tick_seconds=0.01
        )
    assert "a process ran out of runs; 2 searches in flight or runs not started" in caplog.text
    err = capfd.readouterr().err
    # How many rounds it takes depends on the processes' timing (under load a batch can
    # yield again right after a refill); that it is dealt out and resumed is the behaviour.
    assert err.count("searches yielded") >= 1
    assert err.count("resumed 1 searches in flight") >= 2
    assert sorted((s["p"], s["run"]) for s in summaries) == sorted(jobs)  # each once
    assert not inflight_checkpoints(tmp_path)
    trials, digest = stored(tmp_path)
    want = serial_two_runs[0].set_index(["p", "run"]).loc[jobs].reset_index()
    trials = trials.sort_values(["p", "run", "index"], ascending=[False, True, True])
    pd.testing.assert_frame_equal(trials.reset_index(drop=True), want)
    for key, value in digest.items():
        if isinstance(value, pd.DataFrame):
            pd.testing.assert_frame_equal(value, serial_two_runs[1][key], check_exact=True)
        else:
            assert value == serial_two_runs[1][key], key


def test_a_batch_that_cannot_write_its_checkpoint_keeps_its_searches(
    serial, tmp_path, monkeypatch, caplog
):
    import lonlib.experiment.lockstep
    from lonlib.experiment.lockstep import run_lockstep
    from lonlib.storage.atomic import DataWriteError

    def disk_full(*_args, **_kwargs):
        raise DataWriteError("no space left on device (test)")

    monkeypatch.setattr(lonlib.experiment.lockstep, "save_inflight", disk_full)
    asked = []
    jobs = [(p, run) for p in CONFIG.perturbations for run in range(CONFIG.runs)]
    summaries = []
    with caplog.at_level("INFO", logger="lonlib"):
        yielded = run_lockstep(
            tmp_path,
            CONFIG,
            jobs,
            summaries.append,
            slots=4,
            tick_seconds=0,
            checkpoint_seconds=0,  # every step tries (and fails) to write one
            should_yield=lambda: asked.append(True) or True,
        )
    assert not yielded and len(asked) == 1  # asked once: it said it could not, and went on
    assert "could not yield; its searches continue in this batch" in caplog.text
    assert sorted((s["p"], s["run"]) for s in summaries) == sorted(jobs)
    assert not list((tmp_path / ".inflight").iterdir())  # one checkpoint path, lock removed
    pd.testing.assert_frame_equal(stored(tmp_path)[0], serial[0])


def killed_after_checkpoints(monkeypatch, folder, config, slots, writes):
    """Run ``config`` into ``folder`` through one lockstep batch of ``slots`` that writes an
    in-flight checkpoint every step and dies right after its ``writes``-th."""
    import lonlib.experiment.lockstep

    save = lonlib.experiment.lockstep.save_inflight
    calls = []

    def save_then_die(*args, **kwargs):
        save(*args, **kwargs)
        calls.append(args[0])
        if len(calls) == writes:
            raise KeyboardInterrupt

    monkeypatch.setattr(lonlib.experiment.lockstep, "save_inflight", save_then_die)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(
            config, folder, progress=False, executor="lockstep", slots=slots, checkpoint_seconds=0
        )
    monkeypatch.undo()


def _kill_small(folder):
    with pytest.MonkeyPatch.context() as monkeypatch:
        killed_after_checkpoints(monkeypatch, folder, SMALL, slots=2, writes=70)


@pytest.fixture
def small_killed(tmp_path_factory):
    """Copies into a folder SMALL killed after the 70th checkpoint of its batch of 2 slots
    (:func:`killed_after_checkpoints`): that experiment is run once per session."""
    shared = built_once(tmp_path_factory, "small-killed", _kill_small)

    def copy_into(folder):
        shutil.copytree(shared, folder, dirs_exist_ok=True)

    return copy_into


def test_a_lockstep_batch_killed_mid_search_resumes_from_its_checkpoint(
    serial, tmp_path, monkeypatch, caplog, device_mode
):
    import lonlib.experiment.checkpoints
    from lonlib.storage.inflight import inflight_checkpoints

    writes = []
    write = lonlib.experiment.checkpoints.atomic_write

    def die_committing_the_150th(path, data):  # every step writes one: mid-search
        writes.append(path)
        if len(writes) == 2 * 150:  # its data file is written, its metadata is not
            raise KeyboardInterrupt
        write(path, data)

    monkeypatch.setattr(lonlib.experiment.checkpoints, "atomic_write", die_committing_the_150th)
    with pytest.raises(KeyboardInterrupt):
        run_experiment(
            CONFIG, tmp_path, progress=False, executor="lockstep", slots=4, checkpoint_seconds=0
        )
    monkeypatch.undo()
    (checkpoint,) = inflight_checkpoints(tmp_path)  # the 149th, whole
    assert len(checkpoint.runs) == 4 and checkpoint.steps == (149,) * 4
    assert len(list((tmp_path / ".inflight").glob("*.pt"))) == 2  # the 149th and the 150th's
    table = status(tmp_path).set_index("p")
    assert table["saved_in_flight"].sum() == 4
    assert table["saved_env_steps"].sum() == 4 * 149
    runs = run_status(tmp_path)
    assert runs["in_flight"].sum() == 4 and set(runs["in_flight_steps"]) <= {0, 149}
    assert read_experiment_trials(tmp_path).empty  # nothing stored: all was in flight
    with caplog.at_level("INFO", logger="lonlib.experiment.lockstep"):
        run_experiment(CONFIG, tmp_path, progress=False, executor="lockstep", slots=4)
    assert "resumed 4 searches in flight (596 env steps)" in caplog.text
    trials, digest = stored(tmp_path)
    pd.testing.assert_frame_equal(trials, serial[0])
    for key, value in digest.items():
        if isinstance(value, pd.DataFrame):
            pd.testing.assert_frame_equal(value, serial[1][key], check_exact=True)
        else:
            assert value == serial[1][key], key
    assert not list((tmp_path / ".inflight").iterdir())  # the finished batch removed it all


SMALL = dataclasses.replace(CONFIG, perturbations=(1e-3,), runs=2)


@pytest.mark.parametrize("change", ["trials", "ended", "start", "all", "truncated", "threads"])
def test_a_checkpoint_continues_only_the_slots_whose_runs_did_not_go_on(
    serial, tmp_path, small_killed, monkeypatch, caplog, change
):
    import json

    from lonlib.experiment.checkpoints import load_inflight, save_inflight
    from lonlib.storage.inflight import inflight_checkpoints

    small_killed(tmp_path)
    (checkpoint,) = inflight_checkpoints(tmp_path)
    if change in ("trials", "all"):  # as if runs had stored a trial after the write
        meta = json.loads(checkpoint.metadata_path.read_text())
        meta["trials"] = [n + 1 for n in meta["trials"]]
        if change == "trials":
            meta["trials"][1] -= 1
        checkpoint.metadata_path.write_text(json.dumps(meta))
    elif change == "ended":  # run 1 was taken to its end by another executor
        run_one(tmp_path, SMALL, 1e-3, 1)
    elif change == "truncated":
        data = checkpoint.data_path.read_bytes()
        checkpoint.data_path.write_bytes(data[: len(data) // 2])
    else:
        trainer = load_inflight(checkpoint)
        if change == "start":  # the slot holds a search its run does not ask for
            trainer.searches[0].theta = trainer.searches[0].theta + 1e-3
        else:
            trainer.hp = dataclasses.replace(trainer.hp, threads=2)
        counts = dict(zip(checkpoint.runs, checkpoint.trials, strict=True))
        save_inflight(checkpoint.metadata_path, trainer, counts)
    with caplog.at_level("INFO", logger="lonlib.experiment.lockstep"):
        run_experiment(SMALL, tmp_path, progress=False, executor="lockstep", slots=2)
    log = caplog.text
    if change in ("trials", "start", "ended"):
        assert "resumed 1 searches in flight (70 env steps)" in log
        assert "1 whose runs went on since restart" in log
    elif change == "threads":
        assert "trained with threads=2 (this session: 1)" in log and "resumed" not in log
    else:
        assert "stale in-flight checkpoint removed" in log and "resumed" not in log
    want = serial[0][(serial[0]["p"] == 1e-3) & (serial[0]["run"] < 2)].reset_index(drop=True)
    pd.testing.assert_frame_equal(stored(tmp_path)[0], want)
    assert not list((tmp_path / ".inflight").iterdir())


def fake_checkpoint(out, runs, trials):
    """Metadata of a checkpoint (no data file): enough for dealing runs and removing it."""
    import json

    from lonlib.storage.inflight import FORMAT

    folder = out / ".inflight"
    folder.mkdir(exist_ok=True)
    batch, write = "0123456789ab", "ba9876543210"  # ids as lonlib makes them
    meta = {"format": FORMAT, "write_id": write, "data": f"{batch}.{write}.pt", "saved": 0}
    meta |= {"runs": runs, "trials": trials, "steps": [10] * len(runs)}
    (folder / f"{batch}.json").write_text(json.dumps(meta))
    return folder


def test_processes_resume_the_checkpoints_of_their_runs(tmp_path):
    from lonlib.experiment.lockstep_workers import split_jobs

    fake_checkpoint(tmp_path, runs=[[0.001, 3], [0.0001, 0]], trials=[2, 0])
    jobs = [(0.001, run) for run in range(4)] + [(0.0001, run) for run in range(4)]
    groups = split_jobs(tmp_path, jobs, workers=2)
    assert groups[0][:2] == [(0.001, 3), (0.0001, 0)]
    assert sorted(groups[0] + groups[1]) == sorted(jobs)
    assert abs(len(groups[0]) - len(groups[1])) <= 1
    assert split_jobs(tmp_path, jobs, workers=2, checkpoints=False)[0][0] == (0.001, 0)


def test_a_checkpoint_split_over_processes_continues_each_part_exactly(
    serial, tmp_path, monkeypatch, caplog
):
    from lonlib.experiment.checkpoints import split_inflight
    from lonlib.storage.inflight import inflight_checkpoints

    killed_after_checkpoints(monkeypatch, tmp_path, CONFIG, slots=8, writes=120)
    (whole,) = inflight_checkpoints(tmp_path)
    split_inflight(whole, parts=3)
    parts = inflight_checkpoints(tmp_path)
    assert sorted(len(part.runs) for part in parts) == [2, 3, 3]
    assert sorted(run for part in parts for run in part.runs) == sorted(whole.runs)
    assert all(part.steps == (120,) * len(part.runs) for part in parts)
    with caplog.at_level(
        "INFO", logger="lonlib.experiment.lockstep"
    ):  # one process: one part resumed
        run_experiment(CONFIG, tmp_path, progress=False, executor="lockstep", slots=8)
    assert "resumed 3 searches in flight (360 env steps)" in caplog.text
    pd.testing.assert_frame_equal(stored(tmp_path)[0], serial[0])
    assert not inflight_checkpoints(tmp_path)  # the parts left behind went with their runs


def test_a_subset_of_a_batch_continues_its_searches_exactly(device_mode):
    from lonlib.ddpg.trainer import SlotTrainer
    from lonlib.task.policy import actor_spec, critic_spec

    rng = np.random.default_rng(0)
    k = 3
    thetas = rng.uniform(-0.3, 0.3, (k, actor_spec(1).n_params))
    omegas = rng.uniform(-0.3, 0.3, (k, critic_spec(1).n_params))
    whole = SlotTrainer(thetas, omegas, [5, 6, 7], CONFIG.env, CONFIG.ddpg, tags="abc")
    whole.judge_batch = 100  # greedy evaluations stay queued: the subset must take its own
    for _ in range(130):
        assert not whole.step()
    assert {id(item[0]) for item in whole.pending} >= {id(s) for s in whole.searches}
    part = copy.deepcopy(whole).subset([0, 2])  # nothing shared with the whole
    full = copy.deepcopy(whole)  # a whole copy: its learner's Adam tables must stay joined

    def finish(trainer):
        ended = {}
        while trainer.busy.any():
            for tag, result in trainer.step():
                ended[tag] = result
        return ended

    got, copied, want = finish(part), finish(full), finish(whole)
    assert got.keys() == {"a", "c"} and copied.keys() == {"a", "b", "c"}
    for tag, result in copied.items():
        assert result.fitness == want[tag].fitness and result.env_steps == want[tag].env_steps
        np.testing.assert_array_equal(result.theta, want[tag].theta)
    for tag, result in got.items():
        assert result.fitness == want[tag].fitness and result.env_steps == want[tag].env_steps
        np.testing.assert_array_equal(result.theta, want[tag].theta)
        strip = [{**vars(r), "seconds": 0} for r in result.history]
        assert strip == [{**vars(r), "seconds": 0} for r in want[tag].history]


def test_a_live_batchs_checkpoint_is_never_removed_as_ended(tmp_path):
    from lonlib.experiment.running import remove_finished_checkpoints
    from lonlib.storage.inflight import checkpoint_lock_path, inflight_checkpoints
    from lonlib.storage.lock import exclusive_lock

    folder = fake_checkpoint(tmp_path, runs=[[0.001, 0]], trials=[3])
    (checkpoint,) = inflight_checkpoints(tmp_path)
    with exclusive_lock(checkpoint_lock_path(checkpoint)):  # its batch trains on
        remove_finished_checkpoints(tmp_path, todo=[])
        assert inflight_checkpoints(tmp_path) == [checkpoint]
    remove_finished_checkpoints(tmp_path, todo=[(0.001, 1)])  # its run has ended
    assert not inflight_checkpoints(tmp_path)
    assert not list(folder.iterdir())


def test_sparse_judging_gives_the_serial_trials_and_judges_fewer_policies(tmp_path):
    sparse = dataclasses.replace(CONFIG.ddpg, judge_every=50)
    config = dataclasses.replace(CONFIG, runs=2, ddpg=sparse)  # 4 runs through 3 slots
    run_experiment(config, tmp_path / "serial", progress=False, executor="serial")
    run_experiment(config, tmp_path / "batch", progress=False, executor="lockstep", slots=3)
    (trials, digest), (want_trials, want_digest) = (
        stored(tmp_path / name) for name in ("batch", "serial")
    )
    pd.testing.assert_frame_equal(trials, want_trials)
    assert digest.keys() == want_digest.keys()
    histories = [value for value in digest.values() if isinstance(value, pd.DataFrame)]
    for key, value in digest.items():
        if isinstance(value, pd.DataFrame):
            pd.testing.assert_frame_equal(value, want_digest[key], check_exact=True)
        else:
            assert value == want_digest[key], key
    judged = pd.concat(histories)["greedy_fitness"].notna()
    assert 0 < judged.sum() < 0.8 * len(judged)  # episodes of <= 40 steps, judged every 50
