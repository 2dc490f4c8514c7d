"""Replay buffers of ``k`` agents in one tensor, each slot with its own fill level.

A row packs ``(s, a, r, s', 1 - terminated)``, so a minibatch of every agent is one
``index_select``. Slots are independent ring buffers: a slot can be emptied and reused by a
new local search while the others keep their transitions (the lockstep executor).
Everything lives on the device, the write positions and fill levels too: storing a step
copies only the environment's outputs ``(r, s', 1 - terminated)`` there; ``s`` and ``a``
are on the device already (:mod:`lonlib.ddpg.devices`).
"""

from __future__ import annotations

import numpy as np
import torch

from lonlib.ddpg.devices import copy_to_device, host_tensor, to_device, to_host
from lonlib.ddpg.plain_state import TensorReader
from lonlib.task.pendulum import StepResult
from lonlib.util.plain_data import StateLayoutError


def row_width(obs_size: int, act_size: int) -> int:
    """Floats per stored transition ``(s, a, r, s', 1 - terminated)``."""
    return 2 * obs_size + act_size + 2


class ReplayBuffer:
    """``k`` ring buffers of transitions in one torch tensor ``[k, capacity, width]``."""

    def __init__(
        self, agents: int, capacity: int, obs_size: int, act_size: int, device: torch.device
    ) -> None:
        self.obs_size, self.act_size = obs_size, act_size
        width = row_width(obs_size, act_size)
        self.data = torch.zeros(agents, capacity, width, device=device)
        self.capacity = capacity
        self.device = torch.device(device)
        # the next row each slot writes and the rows it holds, int64 [k] on the device
        self.position = torch.zeros(agents, dtype=torch.int64, device=device)
        self.size = torch.zeros(agents, dtype=torch.int64, device=device)
        self._row = torch.zeros(agents, width, device=device)
        self._outcome = np.zeros((agents, obs_size + 2), dtype=np.float32)  # (r, s', not done)
        self._agents = torch.arange(agents, device=device)
        self._offsets = self._agents[:, None] * capacity

    @property
    def agents(self) -> int:
        """Number of slots ``k``."""
        return self.data.shape[0]

    def clear(self, agent: int) -> None:
        """Empty slot ``agent`` (its old rows are never sampled again)."""
        self.position[agent] = self.size[agent] = 0

    def select(self, index: list[int]) -> ReplayBuffer:
        """A buffer holding only the slots at ``index``, in that order."""
        out = ReplayBuffer(len(index), self.capacity, self.obs_size, self.act_size, self.device)
        rows = to_device(index, self.device, torch.int64)
        for name in ("data", "position", "size"):
            getattr(out, name).copy_(getattr(self, name)[rows])
        return out

    def state_tensors(self) -> dict[str, torch.Tensor]:
        """The buffer as CPU tensors: ``position`` and ``size`` ``[k]`` and ``rows``, each
        slot's rows in use one slot after another (``[sum(size), width]``). Rows past a
        slot's fill level are left from an earlier search and never read, so they are not
        kept. The rows are gathered on the device and copied to the host once (on the CPU
        the gathered tensor is the export: the rows are held twice at most, the buffer and
        the export, never a third time)."""
        size = to_host(self.size)
        rows = torch.cat([self.data[i, :n] for i, n in enumerate(size.tolist())])
        return {
            "position": host_tensor(to_host(self.position)),
            "size": host_tensor(size),
            "rows": host_tensor(to_host(rows, temporary=True)),
        }

    @classmethod
    def from_state(
        cls,
        reader: TensorReader,
        prefix: str,
        agents: int,
        capacity: int,
        obs_size: int,
        act_size: int,
        device: torch.device,
    ) -> ReplayBuffer:
        """A buffer continuing from :meth:`state_tensors` (names after ``prefix``), every
        tensor checked against this buffer's layout first (:class:`StateLayoutError`). Each
        slot's rows are copied straight into the buffer (no copy of all rows first)."""
        position = reader.take_numpy(f"{prefix}position", (agents,), torch.int64)
        size = reader.take_numpy(f"{prefix}size", (agents,), torch.int64)
        # A slot fills from row 0 after each clear, so below capacity it writes at its size.
        wrong_size = (size < 0) | (size > capacity)
        wrong_position = (position < 0) | (position >= capacity)
        wrong_position |= (size < capacity) & (position != size)
        if (wrong_size | wrong_position).any():
            raise StateLayoutError(f"{prefix}: fill levels or positions outside the buffer")
        width = row_width(obs_size, act_size)
        rows = reader.take(f"{prefix}rows", (int(size.sum()), width), torch.float32, finite=True)
        out = cls(agents, capacity, obs_size, act_size, device)  # allocated once all fit
        for i, part in enumerate(torch.split(rows, size.tolist())):
            if len(part):
                copy_to_device(part, out.data[i, : len(part)])
        out.position, out.size = to_device(position, out.device), to_device(size, out.device)
        return out

    def add_step(
        self, obs: torch.Tensor, actions: torch.Tensor, outcome: StepResult, next_obs: np.ndarray
    ) -> torch.Tensor:
        """Store one environment step of every agent (``obs``, ``actions`` on the device;
        the environment's ``outcome`` and ``next_obs`` on the host). Only a true end of the
        task (collision, tether, boundary) is stored as terminal; reaching the step limit is
        a truncation, and the target still bootstraps from its next state. Returns
        :meth:`add`'s ``s'`` on the device."""
        return self.add(obs, actions, outcome.reward, next_obs, outcome.terminated)

    def add(
        self,
        obs: torch.Tensor,
        actions: torch.Tensor,
        rewards: np.ndarray,
        next_obs: np.ndarray,
        terminated: np.ndarray,
    ) -> torch.Tensor:
        """Store one transition per agent (a leading agent dimension), each at its slot's
        own position: ``s`` and ``a`` are device tensors, the rest (the environment's
        outputs) host arrays that cross in one copy. Returns the stored ``s'`` on the device
        ``[k, o]`` (a view, valid until the next call)."""
        o, a = self.obs_size, self.act_size
        outcome = self._outcome  # the row's tail (r, s', not done), packed on the host
        outcome[:, 0] = rewards
        outcome[:, 1 : o + 1] = next_obs
        outcome[:, -1] = ~terminated
        row = self._row
        row[:, :o] = obs
        row[:, o : o + a] = actions
        copy_to_device(outcome, row[:, o + a :])
        self.data[self._agents, self.position] = row
        self.position.add_(1).remainder_(self.capacity)
        self.size.add_(1).clamp_(max=self.capacity)
        return row[:, o + a + 1 : 2 * o + a + 1]

    def sample(self, indices: torch.Tensor | np.ndarray) -> tuple[torch.Tensor, ...]:
        """Transitions at ``indices [k, batch]`` (agent ``i`` reads only its own buffer):
        ``(s, a, r, s', not_done)``, each ``[k, batch, ...]``."""
        if not isinstance(indices, torch.Tensor):
            indices = to_device(indices, self.device, torch.int64)
        idx = indices + self._offsets
        flat = self.data.view(-1, self.data.shape[-1])
        batch = flat.index_select(0, idx.view(-1)).view(*idx.shape, -1)
        o, a = self.obs_size, self.act_size
        return (
            batch[..., :o],
            batch[..., o : o + a],
            batch[..., o + a : o + a + 1],
            batch[..., o + a + 1 : 2 * o + a + 1],
            batch[..., -1:],
        )
