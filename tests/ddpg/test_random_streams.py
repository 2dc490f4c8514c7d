"""Counter-based streams: an agent's numbers depend only on its seed, purpose and counter."""

import numpy as np
import pytest
import torch

from lonlib.ddpg.devices import cpu_as_device
from lonlib.ddpg.streams import (
    EXPLORATION_NOISE,
    REPLAY_SAMPLES,
    START_NOISE,
    WARMUP_ACTIONS,
    CounterStreams,
)


def torch_backend(seeds):
    """Streams computed with the torch int64 backend (what CUDA uses) on the CPU."""
    with cpu_as_device():
        return CounterStreams(seeds)


def test_an_agents_draws_do_not_depend_on_the_batch_or_its_row():
    seeds = [7, 2**64 - 1, 0, 123456789]
    counters = np.array([3, 10, 0, 99])
    together = CounterStreams(seeds)
    for draw in ("uniform", "normal"):
        batch = getattr(together, draw)(EXPLORATION_NOISE, counters, 5)
        for i, seed in enumerate(seeds):
            alone = getattr(CounterStreams([seed]), draw)(EXPLORATION_NOISE, counters[i : i + 1], 5)
            assert torch.equal(batch[i], alone[0])
    reordered = CounterStreams(seeds[::-1]).uniform(WARMUP_ACTIONS, counters[::-1], 3)
    assert torch.equal(reordered.flip(0), together.uniform(WARMUP_ACTIONS, counters, 3))


def test_purposes_counters_and_seeds_give_different_numbers():
    streams = CounterStreams([1, 1])
    a = streams.uniform(WARMUP_ACTIONS, np.array([0, 1]), 4)
    assert not torch.equal(a[0], a[1])  # same seed, other counter
    b = streams.uniform(EXPLORATION_NOISE, np.array([0, 1]), 4)
    assert not torch.equal(a, b)  # other purpose
    c = CounterStreams([2, 2]).uniform(WARMUP_ACTIONS, np.array([0, 1]), 4)
    assert not torch.equal(a, c)  # other seed


def test_distributions():
    streams = CounterStreams([11, 12])
    u = streams.uniform(WARMUP_ACTIONS, np.array([0, 0]), 200_000)
    assert u.min() >= 0.0 and u.max() < 1.0
    assert u.mean().item() == pytest.approx(0.5, abs=0.005)
    assert u.var().item() == pytest.approx(1 / 12, rel=0.02)
    z = streams.normal(EXPLORATION_NOISE, np.array([5, 5]), 200_000)
    assert z.mean().item() == pytest.approx(0.0, abs=0.01)
    assert z.std().item() == pytest.approx(1.0, rel=0.01)
    assert (z.abs() > 3).float().mean().item() == pytest.approx(0.0027, abs=0.001)
    k = streams.integers(REPLAY_SAMPLES, np.array([1, 1]), 100_001, np.array([7, 40_000]))
    assert k.dtype == torch.int64 and k.shape == (2, 100_001)
    counts = np.bincount(k[0].numpy(), minlength=7)
    assert counts.size == 7 and counts.min() > 0.95 * 100_001 / 7
    assert k[1].min() >= 0 and k[1].max() < 40_000 and len(np.unique(k[1])) > 35_000


def test_the_torch_backend_draws_the_same_numbers_as_the_numpy_one():
    seeds, counters = [3, 2**63 + 5, 0], np.array([0, 7, 2**40])
    cpu, emulated = CounterStreams(seeds), torch_backend(seeds)
    for purpose in (WARMUP_ACTIONS, REPLAY_SAMPLES):
        assert torch.equal(
            cpu.uniform(purpose, counters, 9), emulated.uniform(purpose, counters, 9)
        )
    high = np.array([5, 40_000, 2**31 - 1])
    assert torch.equal(
        cpu.integers(REPLAY_SAMPLES, counters, 11, high),
        emulated.integers(REPLAY_SAMPLES, counters, 11, high),
    )
    # counters and bounds already on the device (the lockstep step's) draw the same
    on_device = torch.from_numpy(counters), torch.from_numpy(high)
    for streams in (cpu, emulated):
        assert torch.equal(
            streams.integers(REPLAY_SAMPLES, *on_device[:1], 11, on_device[1]),
            cpu.integers(REPLAY_SAMPLES, counters, 11, high),
        )


@pytest.mark.parametrize("backend", [CounterStreams, torch_backend])
def test_numbers_the_host_consumes_are_the_streams_numbers_drawn_on_the_host(backend):
    streams = backend([4, 2**64 - 3])
    streams.set_seed(1, 99)
    counters = np.array([12, 2**33])
    host = streams.host_uniform(START_NOISE, counters, 8)
    assert isinstance(host, np.ndarray) and host.dtype == np.float64
    np.testing.assert_array_equal(host, streams.uniform(START_NOISE, counters, 8).numpy())


@pytest.mark.parametrize("seed", [-1, 2**64, 1.5, True, "7"])
def test_bad_seeds_are_refused(seed):
    with pytest.raises(ValueError, match="seed must be an integer"):
        CounterStreams([seed])


def test_no_two_purposes_share_draws_at_nearby_counters():
    streams = CounterStreams([9])
    purposes = (WARMUP_ACTIONS, EXPLORATION_NOISE, REPLAY_SAMPLES, START_NOISE)
    words = {
        (q, c): tuple(streams.uniform(q, np.array([c]), 2)[0].tolist())
        for q in purposes
        for c in range(64)
    }
    assert len(set(words.values())) == len(words)


@pytest.mark.parametrize("backend", [CounterStreams, torch_backend])
def test_counters_and_bounds_as_tensors_must_be_int64_on_the_streams_device(backend):
    # an int32 tensor would hash other words (c * 2^8 wraps in 32 bits), a tensor on another
    # device would fail there or be copied each draw
    streams = backend([1, 2])
    narrow = torch.tensor([3, 2**30], dtype=torch.int32)
    with pytest.raises(ValueError, match="counters must be .* int64 tensor on the streams'"):
        streams.uniform(WARMUP_ACTIONS, narrow, 2)
    with pytest.raises(ValueError, match="high must be .* got a torch.int32 tensor on cpu"):
        streams.integers(REPLAY_SAMPLES, np.array([1, 2]), 4, narrow)
    elsewhere = torch.zeros(2, dtype=torch.int64, device="meta")
    with pytest.raises(ValueError, match="streams' device cpu, got a torch.int64 tensor on meta"):
        streams.normal(EXPLORATION_NOISE, elsewhere, 2)
    wide = narrow.to(torch.int64)  # the same counters as int64: the numpy counters' words
    assert torch.equal(
        streams.uniform(WARMUP_ACTIONS, wide, 2),
        streams.uniform(WARMUP_ACTIONS, wide.numpy(), 2),
    )


@pytest.mark.parametrize("backend", [CounterStreams, torch_backend])
def test_slots_given_new_seeds_together_draw_as_if_made_with_them(backend):
    streams = backend([1, 2, 3])
    streams.set_seeds([2, 0], [30, 10])
    assert streams.seeds == [10, 2, 30]
    counters = np.array([4, 5, 6])
    assert torch.equal(
        streams.uniform(WARMUP_ACTIONS, counters, 3),
        backend([10, 2, 30]).uniform(WARMUP_ACTIONS, counters, 3),
    )
    with pytest.raises(ValueError, match="2 slots but 1 seeds"):
        streams.set_seeds([0, 1], [5])
    with pytest.raises(ValueError, match="seed must be an integer"):
        streams.set_seeds([0], [-1])
    assert streams.seeds == [10, 2, 30]  # a refused seed changes nothing
