"""Host and device (lonlib.ddpg.devices): every copy a lockstep step and its events make is
counted, per step only the environment's outputs go to the device and the actions come back,
an event copies only what it needs, the CPU can take every path a CUDA device takes (the
`device_mode` fixture), and on torch's meta device (shapes without values; a CPU tensor
mixed into its operations raises, as it fails or waits on CUDA) every tensor of the
learner, the replay, the streams and the trainer stays on the device."""

import contextlib
import dataclasses
import itertools
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.overrides import TorchFunctionMode

import lonlib
import lonlib.ddpg.devices as devices
import lonlib.ddpg.trainer as trainer_module
from lonlib.config import DDPGConfig, PendulumConfig
from lonlib.ddpg.checkpoint import from_checkpoint, to_checkpoint
from lonlib.ddpg.devices import (
    Transfer,
    TransferLog,
    copy_to_device,
    cpu_as_device,
    host_view,
    is_host,
    to_device,
    to_host,
)
from lonlib.ddpg.lean import LeanDDPG
from lonlib.ddpg.plain_state import TensorReader
from lonlib.ddpg.replay import ReplayBuffer
from lonlib.ddpg.streams import EXPLORATION_NOISE, REPLAY_SAMPLES, WARMUP_ACTIONS, CounterStreams
from lonlib.ddpg.trainer import SlotTrainer, check_device, exploration_actions
from lonlib.task.policy import actor_spec, critic_spec
from tests.conftest import tiny_ddpg

ENV = PendulumConfig(n_carts=1, steps=400)
HP = tiny_ddpg(max_steps=10**6, min_steps=10**6, patience_steps=10**6)
DEVICES_MODULE = "lonlib/ddpg/devices.py"
# the package's folder: a checkout may itself lie in a folder named lonlib
PACKAGE = Path(lonlib.__file__).parent.as_posix() + "/"
A_SIZE, C_SIZE = actor_spec(1).n_params, critic_spec(1).n_params
OBS = ENV.observation_size


def trainer(k=3, hp=HP, env=ENV):
    rng = np.random.default_rng(0)
    thetas = np.stack([actor_spec(env.n_carts).initial(rng) for _ in range(k)])
    omegas = np.stack([critic_spec(env.n_carts).initial(rng) for _ in range(k)])
    return SlotTrainer(thetas, omegas, list(range(10, 10 + k)), env, hp)


def initial_parameters(k):
    rng = np.random.default_rng(1)
    return (
        np.stack([actor_spec(1).initial(rng) for _ in range(k)]),
        np.stack([critic_spec(1).initial(rng) for _ in range(k)]),
    )


def test_the_cpu_is_the_host_unless_the_tests_switch_makes_it_a_device():
    assert is_host("cpu") and is_host(torch.device("cpu")) and not is_host("meta")
    with cpu_as_device():
        assert not is_host("cpu")
        with cpu_as_device():
            assert not is_host("cpu")
        assert not is_host("cpu")  # nested: the outer switch still holds
    assert is_host("cpu")


def test_copies_never_share_memory_and_every_one_is_counted():
    host = np.arange(6, dtype=np.float64).reshape(2, 3)
    with TransferLog() as log:
        tensor = to_device(host, "cpu", torch.float32)
        host[0, 0] = 100.0
        assert tensor.dtype == torch.float32 and tensor[0, 0] == 0.0
        back = to_host(tensor)
        back[1, 1] = -1.0
        assert tensor[1, 1] == 4.0
        out = torch.zeros(2, 3, dtype=torch.float64)
        copy_to_device(host[:, ::-1], out)  # a strided array, cast to out's dtype
        assert out[0, 2] == 100.0
        assert to_device(torch.ones(2), "cpu").dtype == torch.float32
    assert [t.direction for t in log.transfers] == ["to device", "to host"] + ["to device"] * 2
    assert log.count("to device") == 3 and log.count("to host") == 1
    assert log.transfers[0] == Transfer("to device", (2, 3), torch.float32)
    view = host_view(tensor)
    view[0, 1] = 7.0  # a view, not a copy
    assert tensor[0, 1] == 7.0
    with pytest.raises(ValueError, match="host memory"):
        host_view(torch.zeros(1, device="meta"))
    with cpu_as_device(), pytest.raises(ValueError, match="host memory"):
        host_view(tensor)  # the CPU is a device now: no view of its memory
    with pytest.raises(ValueError, match="copies host values"):
        copy_to_device(torch.zeros(3, device="meta"), out)


@pytest.mark.parametrize("host", [True, False])
def test_a_temporarys_memory_is_taken_over_only_in_host_memory(host):
    with TransferLog() as log, cpu_as_device() if not host else contextlib.nullcontext():
        temporary = torch.zeros(3)
        values = to_host(temporary, temporary=True)
        values[0] = 1.0
    assert temporary[0] == (1.0 if host else 0.0)  # a device's is copied, as always
    assert log.transfers == [Transfer("to host", (3,), torch.float32)]  # counted either way


def test_a_cuda_device_is_checked_against_the_devices_torch_sees(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    check_device("cuda")
    check_device("cuda:0")
    with pytest.raises(ValueError, match="this machine has 1 CUDA device"):
        check_device("cuda:1")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(ValueError, match="torch sees no CUDA device here"):
        check_device("cuda")


def _holds_host_data(value) -> bool:
    if isinstance(value, np.ndarray):
        return True
    if isinstance(value, (list, tuple, dict)):
        values = value.values() if isinstance(value, dict) else value
        return any(_holds_host_data(v) for v in values)
    return False


def _mask_index(index) -> bool:
    """Whether an index holds a boolean mask (its result's size depends on its values)."""
    parts = index if isinstance(index, tuple) else (index,)
    return any(isinstance(i, torch.Tensor) and i.dtype in (torch.bool, torch.uint8) for i in parts)


class Crossings(TorchFunctionMode):
    """Records every torch call that moves data between numpy and torch or between
    devices, or waits for a device value, other than the counted copies of
    lonlib/ddpg/devices.py (``to_device``, ``copy_to_device``, ``to_host``): conversions
    (``as_tensor``, ``tensor``, ``from_numpy``, ``numpy``, ``cpu``, ``to`` a device,
    ``item``, ``tolist``, ``__array__``), Python values read from a tensor (``__bool__``,
    ``__float__``...), any call handed a numpy array or a list index (an implicit copy), and
    the operations whose result's size depends on the values (a boolean-mask index,
    ``nonzero``, ``masked_select``, ``unique``, ``repeat_interleave`` by a tensor,
    ``where`` with one argument: on CUDA each waits for the device). The uncounted helpers
    ``host_view`` and ``host_tensor`` are recorded under the caller's name unless the CPU is
    the host (:func:`is_host`: they are its no-copy branch). Each call is ``(name, [where])``
    with ``where`` the innermost lonlib function outside devices.py."""

    NAMES = {"as_tensor", "tensor", "numpy", "cpu", "item", "tolist", "__array__"}
    NAMES |= {"__bool__", "__float__", "__int__", "__index__"}
    SIZED_BY_VALUES = {"nonzero", "argwhere", "masked_select", "unique", "unique_consecutive"}
    COUNTED = {"to_device", "copy_to_device", "to_host", "_record"}

    def __init__(self, monkeypatch):
        super().__init__()
        self.calls = []
        from_numpy = torch.from_numpy

        def counted(array):
            self._record("from_numpy")
            return from_numpy(array)

        monkeypatch.setattr(torch, "from_numpy", counted)

    def _record(self, name):
        frame = sys._getframe(2)
        via, where = None, []
        while frame is not None:
            path = frame.f_code.co_filename.replace("\\", "/")
            if path.endswith(DEVICES_MODULE):
                if frame.f_code.co_name in self.COUNTED:
                    return  # a counted copy: TransferLog's
                via = via or frame.f_code.co_name
            elif path.startswith(PACKAGE):  # named inside the package, wherever it lies
                where.append(f"{path[len(PACKAGE) :]}:{frame.f_code.co_name}")
            frame = frame.f_back
        if via is not None and is_host("cpu"):
            return  # host_view or host_tensor of host memory: the CPU's no-copy branch
        self.calls.append((name if via is None else f"{via} {name}", where[:1]))

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        name = getattr(func, "__name__", str(func))
        moves = name in self.NAMES or name in self.SIZED_BY_VALUES
        if name == "to":  # a dtype change stays on its device
            moves = any(isinstance(a, (str, torch.device)) for a in (*args[1:], *kwargs.values()))
            moves |= "device" in kwargs
        if name in ("__getitem__", "__setitem__"):
            moves |= isinstance(args[1], list) or (
                isinstance(args[1], tuple) and any(isinstance(i, list) for i in args[1])
            )
            moves |= _mask_index(args[1])
        if name == "repeat_interleave":  # by a tensor of counts, unless told the size
            moves = "output_size" not in kwargs and not (len(args) > 1 and isinstance(args[1], int))
        if name == "where":  # torch.where(condition) is nonzero
            moves = len(args) + len(kwargs) == 1
        if moves or _holds_host_data(args) or _holds_host_data(kwargs):
            self._record(name)
        return func(*args, **kwargs)


def test_the_crossings_guard_sees_copies_waits_and_value_sized_results(monkeypatch):
    x, mask = torch.arange(4), torch.tensor([True, False, True, False])
    rows = torch.tensor([0, 2])
    with cpu_as_device():
        for op in (
            lambda: x[mask],
            lambda: x.view(2, 2)[:, mask[:2]],
            lambda: x.__setitem__(mask, 0),
            lambda: x.nonzero(),
            lambda: torch.argwhere(x),
            lambda: x.masked_select(mask),
            lambda: torch.unique(x),
            lambda: x.repeat_interleave(x),
            lambda: torch.where(mask),
            lambda: devices.host_tensor(np.zeros(2)),
            lambda: float(x[0]),
            lambda: x + torch.from_numpy(np.ones(4, dtype=np.int64)),
        ):
            with Crossings(monkeypatch) as crossings:
                op()
            monkeypatch.undo()
            assert len(crossings.calls) == 1, crossings.calls
        with Crossings(monkeypatch) as crossings:  # none of these crosses or waits
            x[rows] = x.repeat_interleave(2)[:2]
            torch.where(mask, x, 0).sum()
            to_host(to_device(np.zeros(3), "cpu"))
        monkeypatch.undo()
        assert crossings.calls == []
    with Crossings(monkeypatch) as crossings:  # the CPU is the host: no copy
        host_view(devices.host_tensor(np.zeros(2)))
    monkeypatch.undo()
    assert crossings.calls == []


def logged(monkeypatch, action):
    """``action()``'s result, the copies it made and the crossings outside the counted
    helpers."""
    with TransferLog() as log, Crossings(monkeypatch) as crossings:
        result = action()
    monkeypatch.undo()
    return result, log.transfers, crossings.calls


def steps_with_logs(trainer, steps, monkeypatch):
    """``steps`` steps, each with its transfers, whether an episode ended, and the crossings
    outside the helper."""
    out = []
    for _ in range(steps):
        episodes = trainer.episodes.copy()
        ended, transfers, crossings = logged(monkeypatch, trainer.step)
        assert not ended
        out.append((transfers, bool((trainer.episodes != episodes).any()), crossings))
    return out


ACTIONS = Transfer("to host", (3, ENV.n_carts), torch.float64)
OUTCOME = Transfer("to device", (3, OBS + 2), torch.float32)  # (r, s', not done)
COUNTERS = Transfer("to device", (2, 3), torch.int64)  # steps and busy, after an event
RESET_OBS = Transfer("to device", (3, OBS), torch.float32)


def slot_indices(m):
    return Transfer("to device", (m,), torch.int64)


def parameters_back(m):
    """The Actors and Critics of ``m`` slots, copied to the host."""
    return [
        Transfer("to host", (m, A_SIZE), torch.float32),
        Transfer("to host", (m, C_SIZE), torch.float32),
    ]


def test_a_training_step_copies_the_environments_outputs_in_and_the_actions_out(
    device_mode, monkeypatch
):
    batch = trainer()
    for _ in range(HP.warmup_steps + 5):  # the first updates restore the warm-up's slots
        batch.step()
    steady = [
        (transfers, crossings)
        for transfers, ended, crossings in steps_with_logs(batch, 60, monkeypatch)
        if not ended
    ]
    assert len(steady) >= 30
    for transfers, crossings in steady:
        assert transfers == [ACTIONS, OUTCOME]
        assert crossings == []  # nothing else crossed: replay, masks, Adam on the device


def test_an_episode_end_copies_the_ended_slots_parameters_loss_sums_and_reset_observations(
    device_mode, monkeypatch
):
    batch = trainer()
    for _ in range(HP.warmup_steps + 5):
        batch.step()
    ends = [(t, c) for t, ended, c in steps_with_logs(batch, 150, monkeypatch) if ended]
    assert ends
    for transfers, crossings in ends:
        ended = transfers[2].shape[0]  # how many episodes ended in that step
        assert 1 <= ended < 3
        assert transfers == [
            ACTIONS,
            OUTCOME,
            slot_indices(ended),  # the slots whose episodes ended
            *parameters_back(ended),  # their Actors to judge and their Critics, only theirs
            Transfer("to host", (2, ended), torch.float64),  # their loss sums
            RESET_OBS,
        ]
        assert crossings == []


def test_searches_starting_and_stopping_send_their_keys_parameters_and_counters_once(
    device_mode, monkeypatch
):
    # long episodes: no training episode ends, so a search stops with a final evaluation
    hp = dataclasses.replace(HP, warmup_steps=10, max_steps=40, min_steps=0)
    batch = trainer(3, hp)
    thetas, omegas = initial_parameters(2)
    keys = [] if device_mode == "cpu" else [Transfer("to device", (3,), torch.int64)]
    for _ in range(5):
        batch.step()
    _, transfers, crossings = logged(monkeypatch, lambda: batch.drop([0, 2]))
    assert transfers == [] and crossings == []  # the counters wait for the next step
    _, transfers, crossings = logged(monkeypatch, batch.step)
    assert transfers == [COUNTERS, ACTIONS, OUTCOME] and crossings == []
    _, transfers, crossings = logged(
        monkeypatch, lambda: batch.start([0, 2], thetas, omegas, [20, 21], ["a", "b"])
    )
    one_start = [
        Transfer("to device", (1, A_SIZE), torch.float32),
        Transfer("to device", (1, C_SIZE), torch.float32),
    ]
    assert transfers == [
        *one_start,  # slot 0's Actor and Critic
        *one_start,  # slot 2's
        *keys,  # every slot's stream key, once
        slot_indices(2),  # the slots whose loss sums restart
        RESET_OBS,
    ]
    assert crossings == []
    stops, changed = [], True  # the refill changed the counters
    while batch.busy.any():
        ended, transfers, crossings = logged(monkeypatch, batch.step)
        assert transfers[:3] == [COUNTERS, ACTIONS, OUTCOME] if changed else [ACTIONS, OUTCOME]
        assert transfers.count(COUNTERS) == changed and crossings == []
        if ended:
            stops.append((len(ended), transfers))
        changed = bool(ended)
    # slot 1 stops first, alone; slots 0 and 2 stop together (no training episode ended:
    # the Actor at the stop is judged, and only the stopping slots' parameters cross)
    assert [count for count, _ in stops] == [1, 2]
    for count, transfers in stops:
        assert transfers[-3:] == [slot_indices(count), *parameters_back(count)]


def test_the_devices_counters_follow_the_hosts_through_refills_stops_and_shrinks(device_mode):
    hp = dataclasses.replace(HP, warmup_steps=20, max_steps=70, min_steps=0, patience_steps=25)
    batch = trainer(3, hp, PendulumConfig(n_carts=1, steps=40))
    thetas, omegas = initial_parameters(4)
    starts, ended = 0, 0
    for step in range(300):
        ended += len(batch.step())
        free = batch.free_slots()
        if free and starts < 4 and (step % 3 == 0 or not batch.busy.any()):  # free a while
            batch.start(
                free[:1],
                thetas[starts : starts + 1],
                omegas[starts : starts + 1],
                [100 + starts],
                [f"refill {starts}"],
            )
            starts += 1
        if step == 120:
            batch.drop([batch.slots - 1])
        if step == 160:
            batch.shrink()
        batch._counters_to_device()  # what the next step does first
        np.testing.assert_array_equal(to_host(batch._device_steps), batch.steps)
        np.testing.assert_array_equal(to_host(batch._device_busy), batch.busy)
        np.testing.assert_array_equal(to_host(batch._obs), batch.obs)
        if not batch.busy.any():
            break
    assert starts == 4 and ended >= 4 and batch.slots < 3


def test_a_search_acts_uniformly_in_its_warm_up_then_by_its_actor_with_noise(device_mode):
    hp = dataclasses.replace(HP, warmup_steps=20)
    batch = trainer(2, hp)
    thetas, omegas = initial_parameters(1)
    seeds = [10, 11]
    sent = []
    step = batch.sim.step
    batch.sim.step = lambda actions: sent.append(actions) or step(actions)
    for count in range(30):
        if count == 6:  # slot 1 restarts: its warm-up ends 6 steps after slot 0's
            batch.drop([1])
            batch.start([1], thetas, omegas, [12], ["late"])
            seeds[1] = 12
        streams = CounterStreams(seeds)
        counters = batch.steps.copy()
        uniform = streams.uniform(WARMUP_ACTIONS, counters, 1).numpy()
        mu = batch.learner.act(torch.from_numpy(batch.obs))
        noise = streams.normal(EXPLORATION_NOISE, counters, 1)
        explore = exploration_actions(mu, noise, hp.noise_std).numpy()
        batch.step()
        want = np.where((counters < hp.warmup_steps)[:, None], uniform, explore)
        np.testing.assert_array_equal(sent[-1], want)
    assert len({tuple(row) for row in sent[-1]}) == 2


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_on_cuda_a_training_step_makes_one_memcpy_each_way():
    from torch.profiler import ProfilerActivity, profile

    batch = trainer(hp=dataclasses.replace(HP, device="cuda"))
    for _ in range(HP.warmup_steps + 5):
        batch.step()
    steady = 0
    for _ in range(60):
        episodes = batch.episodes.copy()
        with profile(activities=[ProfilerActivity.CUDA]) as prof:
            batch.step()
            torch.cuda.synchronize()
        if (batch.episodes != episodes).any():
            continue  # an event: parameters, loss sums and reset observations cross too
        copies = [e.name for e in prof.events() if "Memcpy" in e.name]
        assert sum("HtoD" in name for name in copies) == 1, copies
        assert sum("DtoH" in name for name in copies) == 1, copies
        steady += 1
    assert steady >= 30


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_on_cuda_updates_agree_with_the_cpu_within_the_stated_tolerance():
    # docs/performance.md, *On a GPU*: after identical updates the parameters differ by
    # rounding only, at most 1e-5 of the largest parameter (measured on an H200: 8e-7
    # after 1000 updates of the paper's networks at batch 2000).
    rng = np.random.default_rng(0)
    a_spec, c_spec, k, size = actor_spec(2), critic_spec(2), 4, 2000
    thetas = np.stack([a_spec.initial(rng) for _ in range(k)])
    omegas = np.stack([c_spec.initial(rng) for _ in range(k)])
    hp = DDPGConfig(batch_size=size)
    learners = [
        trainer_module.make_learner(a_spec, c_spec, thetas, omegas, hp, torch.device(d))
        for d in ("cpu", "cuda")
    ]
    obs_size = a_spec.sizes[0]
    for _ in range(200):
        obs = rng.normal(size=(k, size, obs_size)).astype(np.float32)
        arrays = (
            obs,
            rng.uniform(size=(k, size, a_spec.sizes[-1])).astype(np.float32),
            rng.uniform(size=(k, size, 1)).astype(np.float32),
            (obs + 0.05 * rng.normal(size=obs.shape)).astype(np.float32),
            np.ones((k, size, 1), np.float32),
        )
        for learner in learners:
            learner.train(tuple(torch.from_numpy(a).to(learner.device) for a in arrays))
    for name in ("actor_flat", "critic_flat"):
        cpu, cuda = (getattr(learner, name)() for learner in learners)
        assert not np.array_equal(cpu, thetas if name == "actor_flat" else omegas)
        assert np.abs(cpu - cuda).max() <= 1e-5 * np.abs(cpu).max(), name


# ----------------------------------------------------------------- events: shrink, restore
def test_a_shrink_copies_only_the_kept_slots(device_mode, monkeypatch):
    batch = trainer()
    for _ in range(HP.warmup_steps + 5):
        batch.step()
    batch.drop([0])
    _, transfers, crossings = logged(monkeypatch, batch.shrink)
    keys = [] if device_mode == "cpu" else [Transfer("to device", (2,), torch.int64)]
    assert transfers == [
        slot_indices(2),  # the learner's kept rows
        *parameters_back(2),  # their Actors and Critics (a new learner is made from them)
        Transfer("to device", (2, A_SIZE), torch.float32),
        Transfer("to device", (2, C_SIZE), torch.float32),
        Transfer("to device", (2, 20_001), torch.float32),  # the new learner's Adam table
        slot_indices(2),  # the replay's kept rows
        *keys,  # the kept streams' keys
        slot_indices(2),  # the loss sums' and observations' kept rows
    ]
    assert crossings == []


# What a checkpoint does on the host by design: its tensors are CPU tensors, made from
# host arrays (the counted copies' results among them) and checked on the host when read.
ON_THE_HOST = {
    ("from_numpy", "ddpg/checkpoint.py:_tensor"),
    ("from_numpy", "ddpg/checkpoint.py:_rows"),
    ("tensor", "ddpg/checkpoint.py:_searches_to_checkpoint"),
    ("host_tensor from_numpy", "ddpg/checkpoint.py:to_checkpoint"),
    ("host_tensor from_numpy", "ddpg/replay.py:state_tensors"),
    ("__bool__", "ddpg/plain_state.py:take"),
    ("numpy", "ddpg/plain_state.py:take_numpy"),
    ("from_numpy", "ddpg/plain_state.py:take_like"),
}


def checkpoint_crossings(calls):
    """Crossings but those of :data:`ON_THE_HOST`."""
    return [(name, where) for name, where in calls if (name, *where) not in ON_THE_HOST]


def test_a_checkpoint_copies_each_device_tensor_once_and_a_restore_sends_them_back(
    device_mode, monkeypatch
):
    batch = trainer()
    for _ in range(HP.warmup_steps + 5):
        batch.step()
    (plain, tensors), transfers, crossings = logged(monkeypatch, lambda: to_checkpoint(batch))
    params = [(3, A_SIZE)] * 4 + [(3, C_SIZE)] * 4  # online, target, two Adam moments
    sizes = batch.replay.size.tolist()
    width = 2 * OBS + ENV.n_carts + 2
    assert transfers == [
        Transfer("to host", (2, 3), torch.float64),  # the loss sums
        *(Transfer("to host", shape, torch.float32) for shape in params),
        Transfer("to host", (3,), torch.int64),  # Adam step counts
        Transfer("to host", (3,), torch.int64),  # the replay's fill levels
        Transfer("to host", (3,), torch.int64),  # and positions
        Transfer("to host", (sum(sizes), width), torch.float32),  # the rows in use, once
    ]
    assert checkpoint_crossings(crossings) == []
    restored, transfers, crossings = logged(monkeypatch, lambda: from_checkpoint(plain, tensors))
    keys = [] if device_mode == "cpu" else [Transfer("to device", (3,), torch.int64)]
    assert transfers == [
        Transfer("to device", (2, 3), torch.float64),  # the loss sums
        *(Transfer("to device", shape, torch.float32) for shape in params[::4]),  # made
        Transfer("to device", (2, 20_001), torch.float32),  # the Adam table
        *(Transfer("to device", shape, torch.float32) for shape in params),  # loaded
        Transfer("to device", (3,), torch.int64),  # Adam step counts
        *(Transfer("to device", (n, width), torch.float32) for n in sizes),  # each slot's rows
        Transfer("to device", (3,), torch.int64),  # the replay's positions
        Transfer("to device", (3,), torch.int64),  # and fill levels
        *keys,
        Transfer("to device", (3, OBS), torch.float32),  # the observations
    ]
    assert checkpoint_crossings(crossings) == []
    _, transfers, _ = logged(monkeypatch, restored.step)
    assert transfers[:3] == [COUNTERS, ACTIONS, OUTCOME]


def peak_bytes(action) -> int:
    """The most host memory torch holds at once while ``action()`` runs, beyond what it
    held before (allocations and frees in time order)."""
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU], profile_memory=True) as prof:
        action()
    events = sorted(prof.events(), key=lambda event: event.time_range.start)
    return max(itertools.accumulate(event.self_cpu_memory_usage for event in events))


def test_a_replay_checkpoint_holds_its_rows_once_more_not_twice():
    replay = ReplayBuffer(3, 1000, OBS, ENV.n_carts, torch.device("cpu"))
    rng = np.random.default_rng(0)
    for step in range(700):
        count = 3 - (step >= 500)  # slot 2 stops at 500 rows
        replay.add(
            torch.from_numpy(rng.standard_normal((3, OBS), dtype=np.float32)),
            torch.from_numpy(rng.random((3, 1))),
            rng.standard_normal(3),
            rng.standard_normal((3, OBS)),
            rng.random(3) < 0.1,
        )
        if count == 2:
            replay.position[2], replay.size[2] = 500, 500  # undo slot 2's write
    rows = replay.state_tensors()["rows"]
    # the layout of the format: each slot's rows in use one slot after another, its own
    # contiguous float32 storage
    want = torch.cat([replay.data[0, :700], replay.data[1, :700], replay.data[2, :500]])
    assert rows.dtype == torch.float32 and rows.is_contiguous() and torch.equal(rows, want)
    assert rows.untyped_storage().nbytes() == rows.nbytes
    assert peak_bytes(replay.state_tensors) < 1.1 * rows.nbytes  # no second copy
    reader = TensorReader({f"r.{k}": v for k, v in replay.state_tensors().items()})
    restored = peak_bytes(
        lambda: ReplayBuffer.from_state(reader, "r.", 3, 1000, OBS, 1, torch.device("cpu"))
    )
    assert restored < replay.data.nbytes + 0.1 * rows.nbytes  # the buffer, no copy of the rows


# ----------------------------------------------------------------- the meta device
@pytest.fixture
def meta(monkeypatch):
    """DDPG's device is torch's meta device: tensors with shapes and dtypes but no values,
    and any operation mixing in a CPU tensor (but a 0-dim one) raises, as on CUDA. What
    comes to the host comes back as zeros of its shape and dtype (still counted), so that
    the numpy environments can step; the trainer accepts the device (``check_device``
    refuses it outside this fixture)."""
    real = devices.to_host

    def to_host(tensor, temporary=False):
        if tensor.device.type != "meta":
            return real(tensor, temporary)
        devices._record("to host", tensor)
        return np.zeros(tuple(tensor.shape), torch.empty(0, dtype=tensor.dtype).numpy().dtype)

    for module in list(sys.modules.values()):
        if getattr(module, "__name__", "").startswith("lonlib.") and (
            getattr(module, "to_host", None) is real
        ):
            monkeypatch.setattr(module, "to_host", to_host)
    monkeypatch.setattr(trainer_module, "check_device", lambda device: None)
    return torch.device("meta")


def tensors_of(root):
    """``(path, tensor)`` of every tensor reachable from ``root`` through the attributes
    of lonlib's objects, lists, tuples and dicts."""
    found, seen, todo = [], set(), [("", root)]
    while todo:
        path, value = todo.pop()
        if id(value) in seen:
            continue
        seen.add(id(value))
        if isinstance(value, torch.Tensor):
            found.append((path, value))
        elif isinstance(value, dict):
            todo += [(f"{path}[{key!r}]", v) for key, v in value.items()]
        elif isinstance(value, (list, tuple)):
            todo += [(f"{path}[{i}]", v) for i, v in enumerate(value)]
        elif type(value).__module__.startswith("lonlib.") and hasattr(value, "__dict__"):
            todo += [(f"{path}.{key}", v) for key, v in vars(value).items()]
    return found


def assert_on_meta(*objects):
    for item in objects:
        tensors = tensors_of(item)
        assert tensors, item
        assert [(path, t.device) for path, t in tensors if t.device.type != "meta"] == []


def test_copies_to_the_meta_device_land_there(meta):
    for values in (np.zeros((2, 3)), [1, 2], 3.0, torch.zeros(2)):
        assert to_device(values, "meta").device.type == "meta"
    assert to_device(np.zeros(2), meta, torch.int64).dtype == torch.int64
    out = torch.empty(2, 3, device=meta)
    assert copy_to_device(np.ones((2, 3)), out) is out


def test_the_learner_replay_and_streams_compute_on_the_device_they_are_made_on(meta):
    k, obs, act = 3, OBS, ENV.n_carts
    thetas, omegas = initial_parameters(k)
    learner = LeanDDPG(
        actor_spec(1),
        critic_spec(1),
        thetas,
        omegas,
        learning_rate=1e-3,
        gamma=0.99,
        tau=0.01,
        device=meta,
    )
    replay = ReplayBuffer(k, 50, obs, act, meta)
    streams = CounterStreams([1, 2, 3], meta)
    streams.set_seeds([0, 2], [7, 8])
    counters = torch.zeros(k, dtype=torch.int64, device=meta)
    states = torch.zeros(k, obs, device=meta)
    for step in range(3):
        warmup = streams.uniform(WARMUP_ACTIONS, counters, act)
        noise = streams.normal(EXPLORATION_NOISE, np.full(k, step), act)  # host counters
        actions = torch.where(
            counters[:, None] < 2, warmup, exploration_actions(learner.act(states), noise, 0.1)
        )
        states = replay.add(states, actions, np.zeros(k), np.zeros((k, obs)), np.zeros(k, bool))
        indices = streams.integers(REPLAY_SAMPLES, counters, 8, replay.size)
        losses = learner.train(replay.sample(indices))
        counters += 1
    assert losses.device == meta and losses.shape == (2, k)
    learner.reset_agent(1, thetas[0], omegas[0])
    parts = learner.select([2, 0]), replay.select([1]), streams.select([0])
    assert_on_meta(learner, replay, streams, *parts)


def test_a_lockstep_batch_keeps_every_tensor_on_its_device_through_steps_and_events(meta):
    hp = dataclasses.replace(
        HP, device="meta", warmup_steps=20, max_steps=70, min_steps=0, patience_steps=25
    )
    batch = trainer(3, hp, PendulumConfig(n_carts=1, steps=30))
    assert_on_meta(batch)
    thetas, omegas = initial_parameters(3)
    starts, events = 0, set()
    for step in range(200):
        if batch.step():
            events.add("stop")
        free = batch.free_slots()
        if free and starts < 3 and (step % 3 == 0 or not batch.busy.any()):
            batch.start(
                free[:1],
                thetas[starts : starts + 1],
                omegas[starts : starts + 1],
                [100 + starts],
                [starts],
            )
            starts += 1
        if step == 60:
            batch = from_checkpoint(*to_checkpoint(batch))
            events.add("restore")
        if step == 90:
            batch.drop([0])
            batch.shrink()
            events.add("shrink")
        assert_on_meta(batch)
        if not batch.busy.any():
            break
    assert events == {"stop", "restore", "shrink"} and starts == 3
