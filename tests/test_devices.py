"""Host and device (lonlib.ddpg.devices): every copy a lockstep step makes is counted, per
step only the environment's outputs go to the device and the actions come back, and the
CPU can take every path a CUDA device takes (the `device_mode` fixture)."""

import dataclasses
import sys

import numpy as np
import pytest
import torch
from torch.overrides import TorchFunctionMode

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
from lonlib.ddpg.streams import EXPLORATION_NOISE, WARMUP_ACTIONS, CounterStreams
from lonlib.ddpg.trainer import DDPGConfig, SlotTrainer, check_device, exploration_actions
from lonlib.task.pendulum import PendulumConfig
from lonlib.task.policy import actor_spec, critic_spec

ENV = PendulumConfig(n_carts=1, steps=400)
HP = DDPGConfig(
    batch_size=32,
    buffer_size=500,
    warmup_steps=50,
    max_steps=10**6,
    min_steps=10**6,
    patience_steps=10**6,
)
DEVICES_MODULE = "lonlib/ddpg/devices.py"


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


class Crossings(TorchFunctionMode):
    """Records every torch call that moves data between numpy and torch or between
    devices, or waits for a device value, made outside lonlib/ddpg/devices.py: conversions
    (``as_tensor``, ``tensor``, ``from_numpy``, ``numpy``, ``cpu``, ``to`` a device,
    ``item``, ``tolist``, ``__array__``), Python values read from a tensor (``__bool__``,
    ``__float__``...), and any call handed a numpy array or a list index (an implicit
    copy)."""

    NAMES = {"as_tensor", "tensor", "numpy", "cpu", "item", "tolist", "__array__"}
    NAMES |= {"__bool__", "__float__", "__int__", "__index__"}

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
        where = []
        while frame is not None:
            path = frame.f_code.co_filename.replace("\\", "/")
            if path.endswith(DEVICES_MODULE):
                return  # the helper's own copies: counted by TransferLog
            if "/lonlib/" in path:
                where.append(f"{path.split('/lonlib/')[-1]}:{frame.f_lineno}")
            frame = frame.f_back
        self.calls.append((name, where[:1]))

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        name = getattr(func, "__name__", str(func))
        moves = name in self.NAMES
        if name == "to":  # a dtype change stays on its device
            moves = any(isinstance(a, (str, torch.device)) for a in (*args[1:], *kwargs.values()))
            moves |= "device" in kwargs
        if name in ("__getitem__", "__setitem__"):
            moves |= isinstance(args[1], list) or (
                isinstance(args[1], tuple) and any(isinstance(i, list) for i in args[1])
            )
        if moves or _holds_host_data(args) or _holds_host_data(kwargs):
            self._record(name)
        return func(*args, **kwargs)


def steps_with_logs(trainer, steps, monkeypatch):
    """``steps`` steps, each with its transfers, whether an episode ended, and the crossings
    outside the helper."""
    out = []
    for _ in range(steps):
        episodes = trainer.episodes.copy()
        with TransferLog() as log, Crossings(monkeypatch) as crossings:
            assert not trainer.step()
        monkeypatch.undo()
        out.append((log.transfers, bool((trainer.episodes != episodes).any()), crossings.calls))
    return out


def test_a_training_step_copies_the_environments_outputs_in_and_the_actions_out(
    device_mode, monkeypatch
):
    batch = trainer()
    for _ in range(HP.warmup_steps + 5):  # the first updates restore the warm-up's slots
        batch.step()
    obs_size = ENV.observation_size
    steady = [
        (transfers, crossings)
        for transfers, ended, crossings in steps_with_logs(batch, 60, monkeypatch)
        if not ended
    ]
    assert len(steady) >= 30
    for transfers, crossings in steady:
        assert transfers == [
            Transfer("to host", (3, ENV.n_carts), torch.float64),  # the actions
            Transfer("to device", (3, obs_size + 2), torch.float32),  # (r, s', not done)
        ]
        assert crossings == []  # nothing else crossed: replay, masks, Adam on the device


def test_an_episode_end_copies_the_parameters_loss_sums_and_reset_observations(
    device_mode, monkeypatch
):
    batch = trainer()
    for _ in range(HP.warmup_steps + 5):
        batch.step()
    a_size, c_size = actor_spec(1).n_params, critic_spec(1).n_params
    ends = [(t, c) for t, ended, c in steps_with_logs(batch, 150, monkeypatch) if ended]
    assert ends
    for transfers, crossings in ends:
        ended = transfers[4].shape[0]  # how many episodes ended in that step
        assert transfers == [
            Transfer("to host", (3, ENV.n_carts), torch.float64),  # the actions
            Transfer("to device", (3, ENV.observation_size + 2), torch.float32),  # (r, s', done)
            Transfer("to host", (3, a_size), torch.float32),  # the Actors to judge
            Transfer("to host", (3, c_size), torch.float32),  # and their Critics
            Transfer("to device", (ended,), torch.int64),  # the slots whose episodes ended
            Transfer("to host", (2, ended), torch.float64),  # their loss sums
            Transfer("to device", (3, ENV.observation_size), torch.float32),  # reset obs
        ]
        assert crossings == []


def test_the_devices_counters_follow_the_hosts_through_refills_stops_and_shrinks(device_mode):
    hp = dataclasses.replace(HP, warmup_steps=20, max_steps=70, min_steps=0, patience_steps=25)
    batch = trainer(3, hp, PendulumConfig(n_carts=1, steps=40))
    thetas, omegas = initial_parameters(4)
    starts, ended = 0, 0
    for step in range(300):
        ended += len(batch.step())
        free = batch.free_slots()
        if free and starts < 4:
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
