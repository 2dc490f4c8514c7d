"""Counter-based random streams: one independent stream per agent, drawn for all agents at once.

Word ``j`` of step ``c`` for purpose ``q`` of the agent with key ``s`` is a pure function of
``(s, q, c, j)``: a SplitMix64 hash (Steele, Lea & Flood, 2014; the finaliser of
``java.util.SplittableRandom``) applied twice,

    h = mix(s + G * (c * 2^8 + q)),      word = mix(h + G * (j + 1)),

with ``G = 0x9E3779B97F4A7C15``. Nothing is carried from one draw to the next, so an agent's
numbers do not depend on how many other agents are drawn with it, in which row it sits, or
on which device: the hash is exact integer arithmetic, computed with numpy ``uint64`` on the
host (the CPU: fewer, faster operations than torch there) and with torch ``int64`` on a
device (two's complement wrap-around; logical shifts emulated by masking), bit for bit the
same words. Which of the two runs is :func:`lonlib.ddpg.devices.is_host`'s to say (the
CPU takes the device's under the tests' :func:`~lonlib.ddpg.devices.cpu_as_device`). The
counters may be numpy arrays or tensors on the streams' device (the lockstep step keeps
them there: no copy per draw); numbers the host consumes (start noise) are drawn on the
host (:meth:`CounterStreams.host_uniform`).
This is what lets the lockstep executor train many local searches as one batch and still give
every run the trials it would get alone, with no Python loop over agents per step.

Uniforms take a word's top 53 bits; normals use Box-Muller on two uniforms; replay indices
take 32 bits each (two per word) scaled to the agent's buffer size by integer arithmetic.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

from lonlib.ddpg.devices import host_tensor, host_view, is_host, on_device, to_device

GOLDEN = 0x9E3779B97F4A7C15
MIX_1 = 0xBF58476D1CE4E5B9
MIX_2 = 0x94D049BB133111EB
PURPOSE_BITS = 8
SIMD_PAD = 64  # elements: a multiple of any CPU vector loop's chunk (AVX-512: 2 x 16 floats)

# What a stream is drawn for (the ``q`` above): one stream per purpose and agent.
WARMUP_ACTIONS = 1
EXPLORATION_NOISE = 2
REPLAY_SAMPLES = 3
START_NOISE = 4


def _signed(value: int) -> int:
    """A 64-bit unsigned constant as the int64 with the same bits."""
    return value - (1 << 64) if value >= 1 << 63 else value


def check_seed(seed: int) -> int:
    """A seed as a stream key: an integer in [0, 2^64)."""
    if (
        isinstance(seed, bool)
        or not isinstance(seed, (int, np.integer))
        or not (0 <= int(seed) < 1 << 64)
    ):
        raise ValueError(f"seed must be an integer in [0, 2**64), got {seed!r}")
    return int(seed)


def _numpy(values) -> np.ndarray:
    """Counters or bounds as numpy: an array as it is, a CPU tensor viewed in place."""
    return host_view(values) if isinstance(values, torch.Tensor) else np.asarray(values)


class _NumpyWords:
    """The hash on numpy uint64 arrays (the host)."""

    golden, mix_1, mix_2 = np.uint64(GOLDEN), np.uint64(MIX_1), np.uint64(MIX_2)

    @staticmethod
    def keys(seeds: list[int]) -> np.ndarray:
        return np.array(seeds, dtype=np.uint64)

    def mix(self, x: np.ndarray) -> np.ndarray:
        x = x ^ (x >> np.uint64(30))
        x = x * self.mix_1
        x = x ^ (x >> np.uint64(27))
        x = x * self.mix_2
        return x ^ (x >> np.uint64(31))

    def words(self, keys: np.ndarray, counters: np.ndarray, purpose: int, lanes: int):
        c = _numpy(counters).astype(np.uint64)
        step = self.mix(
            keys + (c * np.uint64(1 << PURPOSE_BITS) + np.uint64(purpose)) * self.golden
        )
        offsets = np.arange(1, lanes + 1, dtype=np.uint64) * self.golden
        return self.mix(step[:, None] + offsets)

    @staticmethod
    def top(words: np.ndarray, bits: int) -> np.ndarray:
        return (words >> np.uint64(64 - bits)).astype(np.int64)

    @staticmethod
    def low32(words: np.ndarray) -> np.ndarray:
        return (words & np.uint64(0xFFFFFFFF)).astype(np.int64)

    @staticmethod
    def column(values) -> np.ndarray:
        return _numpy(values).astype(np.int64, copy=False)[:, None]

    @staticmethod
    def concat(parts: list[np.ndarray]) -> np.ndarray:
        return np.concatenate(parts, axis=1)

    @staticmethod
    def tensor(values: np.ndarray, device: torch.device) -> torch.Tensor:
        return host_tensor(values)


_HOST_WORDS = _NumpyWords()


class _TorchWords:
    """The same hash on torch int64 tensors (a device)."""

    golden, mix_1, mix_2 = _signed(GOLDEN), _signed(MIX_1), _signed(MIX_2)

    def __init__(self, device: torch.device) -> None:
        self.device = device

    def keys(self, seeds: list[int]) -> torch.Tensor:
        return to_device([_signed(s) for s in seeds], self.device, torch.int64)

    def on_device(self, values) -> torch.Tensor:
        """Counters or bounds as an int64 tensor on the device: a tensor (there already,
        checked by :class:`CounterStreams`) as it is, host values copied."""
        if isinstance(values, torch.Tensor):
            return values
        return to_device(np.asarray(values, dtype=np.int64), self.device)

    @staticmethod
    def shift(x: torch.Tensor, bits: int) -> torch.Tensor:
        return (x >> bits) & ((1 << (64 - bits)) - 1)

    def mix(self, x: torch.Tensor) -> torch.Tensor:
        x = x ^ self.shift(x, 30)
        x = x * self.mix_1
        x = x ^ self.shift(x, 27)
        x = x * self.mix_2
        return x ^ self.shift(x, 31)

    def words(self, keys: torch.Tensor, counters, purpose: int, lanes: int) -> torch.Tensor:
        c = self.on_device(counters)
        step = self.mix(keys + (c * (1 << PURPOSE_BITS) + purpose) * self.golden)
        offsets = torch.arange(1, lanes + 1, dtype=torch.int64, device=self.device) * self.golden
        return self.mix(step[:, None] + offsets)

    def top(self, words: torch.Tensor, bits: int) -> torch.Tensor:
        return self.shift(words, 64 - bits)

    @staticmethod
    def low32(words: torch.Tensor) -> torch.Tensor:
        return words & 0xFFFFFFFF

    def column(self, values) -> torch.Tensor:
        return self.on_device(values)[:, None]

    @staticmethod
    def concat(parts: list[torch.Tensor]) -> torch.Tensor:
        return torch.cat(parts, dim=1)

    @staticmethod
    def tensor(values: torch.Tensor, device: torch.device) -> torch.Tensor:
        return values


class CounterStreams:
    """Per-agent counter-based streams for ``k`` agents whose draws land on ``device``.

    ``seeds`` are the agents' seeds; ``set_seeds`` gives slots new agents. Every draw takes
    the agents' counters (``[k]`` integers: their own step or episode numbers; a numpy
    array, or an int64 tensor on ``device``) and a purpose and returns a ``[k, lanes]``
    torch tensor on ``device``.
    """

    def __init__(self, seeds: list[int], device: str | torch.device = "cpu") -> None:
        self.device = torch.device(device)
        self._words = _HOST_WORDS if is_host(self.device) else _TorchWords(self.device)
        self.seeds = [check_seed(s) for s in seeds]
        self._set_keys()

    def _set_keys(self) -> None:
        self._keys = self._words.keys(self.seeds)
        self._host_keys = (  # the host's own keys serve host_uniform (once, on the host)
            self._keys if self._words is _HOST_WORDS else _HOST_WORDS.keys(self.seeds)
        )

    def set_seed(self, agent: int, seed: int) -> None:
        """Give slot ``agent`` the stream of ``seed``."""
        self.set_seeds([agent], [seed])

    def set_seeds(self, agents: Sequence[int], seeds: Sequence[int]) -> None:
        """Give slots ``agents`` the streams of ``seeds``, one each: the keys go to the
        device once, however many slots change."""
        if len(agents) != len(seeds):
            raise ValueError(f"{len(agents)} slots but {len(seeds)} seeds")
        checked = [check_seed(seed) for seed in seeds]
        for agent, seed in zip(agents, checked, strict=True):
            self.seeds[agent] = seed
        self._set_keys()

    def select(self, index: list[int]) -> CounterStreams:
        """The streams of the agents at ``index`` (same seeds, fewer rows)."""
        return CounterStreams([self.seeds[i] for i in index], self.device)

    def _checked(self, values, name: str):
        """Counters or bounds as given, refusing a tensor the hash cannot take as it is:
        it must be int64 (``c * 2^8`` and the products wrap in 64 bits: narrower integers
        give other words) and on the streams' device."""
        if isinstance(values, torch.Tensor) and (
            values.dtype != torch.int64 or not on_device(values, self.device)
        ):
            raise ValueError(
                f"{name} must be a numpy array or an int64 tensor on the streams' device "
                f"{self.device}, got a {values.dtype} tensor on {values.device}"
            )
        return values

    def _draw(self, purpose: int, counters, lanes: int):
        counters = self._checked(counters, "counters")
        return self._words.words(self._keys, counters, purpose, lanes)

    def uniform(self, purpose: int, counters, lanes: int) -> torch.Tensor:
        """Uniforms in [0, 1), float64 ``[k, lanes]`` (53 random bits each)."""
        top = self._words.top(self._draw(purpose, counters, lanes), 53)
        return self._words.tensor(top, self.device).double() * 2.0**-53

    def host_uniform(self, purpose: int, counters: np.ndarray, lanes: int) -> np.ndarray:
        """:meth:`uniform`'s numbers computed on the host as a float64 numpy array (for
        numbers the host consumes: no round trip through the device)."""
        words = _HOST_WORDS.words(self._host_keys, counters, purpose, lanes)
        return _HOST_WORDS.top(words, 53).astype(np.float64) * 2.0**-53

    def normal(self, purpose: int, counters, lanes: int) -> torch.Tensor:
        """Standard normals, float64 ``[k, lanes]`` (Box-Muller on two uniforms per lane)."""
        u = self.uniform(purpose, counters, 2 * lanes)
        # Transcendental kernels give other bits in a SIMD loop's body than in its scalar
        # tail; with every agent's lanes padded to whole vectors there is no tail, so an
        # agent's normals do not depend on how many agents are drawn with it.
        width = -(-lanes // SIMD_PAD) * SIMD_PAD
        padded = torch.full((u.shape[0], 2, width), 0.5, dtype=u.dtype, device=u.device)
        padded[:, :, :lanes] = u.view(-1, 2, lanes)
        radius = torch.sqrt(-2.0 * torch.log1p(-padded[:, 0]))
        return (radius * torch.cos((2.0 * math.pi) * padded[:, 1]))[:, :lanes]

    def integers(self, purpose: int, counters, lanes: int, high) -> torch.Tensor:
        """Integers uniform in ``[0, high_i)`` for agent ``i``, int64 ``[k, lanes]``; ``high``
        ``[k]`` below 2^31. Each index is ``(w * high) >> 32`` for 32 random bits ``w`` (two
        per word), so a value's probability is off by at most ``high / 2^32`` relative."""
        words = self._draw(purpose, counters, (lanes + 1) // 2)
        high = self._words.column(self._checked(high, "high"))
        halves = [(h * high) >> 32 for h in (self._words.top(words, 32), self._words.low32(words))]
        return self._words.tensor(self._words.concat(halves)[:, :lanes], self.device)
