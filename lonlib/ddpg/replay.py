"""Replay buffers of ``k`` agents in one tensor, each slot with its own fill level.

A row packs ``(s, a, r, s', 1 - terminated)``, so a minibatch of every agent is one
``index_select``. Slots are independent ring buffers: a slot can be emptied and reused by a
new local search while the others keep their transitions (the lockstep executor).
"""

from __future__ import annotations

import numpy as np
import torch

from lonlib.ddpg.plain_state import StateLayoutError, TensorReader
from lonlib.task.pendulum import StepResult


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
        self.position = np.zeros(agents, dtype=np.int64)  # next row each slot writes
        self.size = np.zeros(agents, dtype=np.int64)  # rows each slot holds
        self._row = np.zeros((agents, width), dtype=np.float32)
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
        out.data.copy_(self.data[torch.as_tensor(index, device=self.device)])
        out.position[:] = self.position[index]
        out.size[:] = self.size[index]
        return out

    def state_tensors(self) -> dict[str, torch.Tensor]:
        """The buffer as CPU tensors: ``position`` and ``size`` ``[k]`` and ``rows``, each
        slot's rows in use one slot after another (``[sum(size), width]``). Rows past a
        slot's fill level are left from an earlier search and never read, so they are not
        kept."""
        rows = torch.cat([self.data[i, :n] for i, n in enumerate(self.size.tolist())])
        return {
            "position": torch.from_numpy(self.position.copy()),
            "size": torch.from_numpy(self.size.copy()),
            "rows": rows.cpu(),  # cat made it: its own storage
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
        tensor checked against this buffer's layout first (:class:`StateLayoutError`)."""
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
            out.data[i, : size[i]] = part.to(out.device)
        out.position[:], out.size[:] = position, size
        return out

    def add_step(
        self, obs: np.ndarray, actions: np.ndarray, outcome: StepResult, next_obs: np.ndarray
    ) -> None:
        """Store one environment step of every agent. Only a true end of the task
        (collision, tether, boundary) is stored as terminal; reaching the step limit is a
        truncation, and the target still bootstraps from its next state."""
        self.add(obs, actions, outcome.reward, next_obs, outcome.terminated)

    def add(
        self,
        obs: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        next_obs: np.ndarray,
        terminated: np.ndarray,
    ) -> None:
        """Store one transition per agent (arrays with a leading agent dimension), each at
        its slot's own position: one host-to-device copy and one indexed write."""
        o, a = self.obs_size, self.act_size
        row = self._row
        row[:, :o] = obs
        row[:, o : o + a] = actions
        row[:, o + a] = rewards
        row[:, o + a + 1 : 2 * o + a + 1] = next_obs
        row[:, -1] = ~terminated
        position = torch.from_numpy(self.position).to(self.device, non_blocking=True)
        self.data[self._agents, position] = torch.from_numpy(row).to(self.device)
        self.position += 1
        self.position %= self.capacity
        np.minimum(self.size + 1, self.capacity, out=self.size)

    def sample(self, indices: torch.Tensor | np.ndarray) -> tuple[torch.Tensor, ...]:
        """Transitions at ``indices [k, batch]`` (agent ``i`` reads only its own buffer):
        ``(s, a, r, s', not_done)``, each ``[k, batch, ...]``."""
        idx = torch.as_tensor(indices, device=self.device) + self._offsets
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
