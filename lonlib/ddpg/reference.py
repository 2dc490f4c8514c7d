"""The straightforward DDPG update: autograd through :class:`~lonlib.ddpg.nets.BatchedMLP` and
``torch.optim.Adam``. It is the reference the lean learner (:mod:`lonlib.ddpg.lean`) is
tested against, and stays selectable with ``DDPGConfig(update="autograd")``.

It is outside the device discipline of the lockstep step (:mod:`lonlib.ddpg.devices`, which
needs the lean learner): it picks fused Adam by device type, copies its losses to the host
with ``.cpu()`` each update and back with ``torch.as_tensor`` (:meth:`AutogradDDPG.train`),
and its parameters with ``.cpu()``, by itself and uncounted.
"""

from __future__ import annotations

import copy

import numpy as np
import torch

from lonlib.ddpg.nets import BatchedMLP
from lonlib.task.policy import NetSpec


def autograd_update(
    batch: tuple[torch.Tensor, ...],
    actor: BatchedMLP,
    critic: BatchedMLP,
    actor_target: BatchedMLP,
    critic_target: BatchedMLP,
    actor_opt: torch.optim.Optimizer,
    critic_opt: torch.optim.Optimizer,
    gamma: float,
    tau: float,
) -> tuple[np.ndarray, np.ndarray]:
    """One DDPG update of every agent; returns per-agent critic and actor losses."""
    obs, actions, rewards, next_obs, not_done = batch
    with torch.no_grad():
        next_q = critic_target(torch.cat([next_obs, actor_target(next_obs)], dim=2))
        target = rewards + gamma * not_done * next_q
    q = critic(torch.cat([obs, actions], dim=2))
    # Per-agent mean losses, summed: each agent's gradient is exactly its own loss's.
    critic_loss = ((q - target) ** 2).mean(dim=(1, 2))
    critic_opt.zero_grad(set_to_none=True)
    critic_loss.sum().backward()
    critic_opt.step()

    # The actor's loss needs the critic's input gradient only, not its weight gradients.
    critic.requires_grad_(False)
    actor_loss = -critic(torch.cat([obs, actor(obs)], dim=2)).mean(dim=(1, 2))
    actor_opt.zero_grad(set_to_none=True)
    actor_loss.sum().backward()
    actor_opt.step()
    critic.requires_grad_(True)

    with torch.no_grad():
        for net, target_net in ((actor, actor_target), (critic, critic_target)):
            torch._foreach_lerp_(target_net.tensors, net.tensors, tau)
    return critic_loss.detach().cpu().numpy(), actor_loss.detach().cpu().numpy()


def _rows(flat: np.ndarray, rows: torch.Tensor | None) -> np.ndarray:
    """The rows ``rows`` of host parameters ``flat [k, P]`` (all of them if ``None``)."""
    return flat if rows is None else flat[rows.cpu().numpy()]


class AutogradDDPG:
    """``k`` agents' Actor, Critic, targets and Adam states, updated by :func:`autograd_update`.

    Same interface as :class:`lonlib.ddpg.lean.LeanDDPG` (without slot resets: the torch
    optimizers keep one step count for all agents): :meth:`reset_agent`, :meth:`select`,
    :meth:`load_state` and :attr:`steps` raise ValueError.
    """

    per_agent_state = False  # one optimizer holds every agent's state

    def __init__(
        self,
        actor: NetSpec,
        critic: NetSpec,
        thetas: np.ndarray,
        omegas: np.ndarray,
        *,
        learning_rate: float,
        gamma: float,
        tau: float,
        device: str | torch.device = "cpu",
    ) -> None:
        device = torch.device(device)
        self.gamma, self.tau = gamma, tau
        self.actor = BatchedMLP(actor, thetas).to(device)
        self.critic = BatchedMLP(critic, omegas).to(device)
        self.actor_target, self.critic_target = (
            copy.deepcopy(self.actor),
            copy.deepcopy(self.critic),
        )
        for target in (self.actor_target, self.critic_target):
            target.requires_grad_(False)
        adam = {"lr": learning_rate, "fused": device.type in ("cpu", "cuda")}
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), **adam)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), **adam)

    @property
    def agents(self) -> int:
        """Number of agents ``k``."""
        return self.actor.agents

    def update(self, batch: tuple[torch.Tensor, ...]) -> tuple[np.ndarray, np.ndarray]:
        """One DDPG update of every agent on ``(s, a, r, s', not_done)``, each ``[k, B, .]``;
        returns the per-agent critic and actor losses ``[k]``."""
        return autograd_update(
            batch,
            self.actor,
            self.critic,
            self.actor_target,
            self.critic_target,
            self.actor_opt,
            self.critic_opt,
            self.gamma,
            self.tau,
        )

    def train(self, batch: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """:meth:`update` with the losses as a ``[2, k]`` tensor."""
        device = self.actor.tensors[0].device
        return torch.as_tensor(np.stack(self.update(batch)), device=device)

    def act(self, obs: torch.Tensor) -> torch.Tensor:
        """Greedy actions ``[k, n]`` of the online Actors for one observation each ``[k, o]``."""
        with torch.no_grad():
            return self.actor(obs[:, None, :])[:, 0, :]

    def actor_flat(self, rows: torch.Tensor | None = None) -> np.ndarray:
        """Online Actor parameters ``[k, P_actor]`` (float32, Eq. 1 order), or only the
        agents at ``rows`` (an int64 index tensor)."""
        return _rows(self.actor.flat(), rows)

    def critic_flat(self, rows: torch.Tensor | None = None) -> np.ndarray:
        """Online Critic parameters ``[k, P_critic]`` (float32, Eq. 1 order), or only the
        agents at ``rows``."""
        return _rows(self.critic.flat(), rows)

    def state(self) -> dict[str, np.ndarray]:
        """Every learned quantity as ``[k, P]`` arrays in Eq. 1 order (for comparisons)."""
        out = {}
        for name, net, target, opt in (
            ("actor", self.actor, self.actor_target, self.actor_opt),
            ("critic", self.critic, self.critic_target, self.critic_opt),
        ):
            out[name] = net.flat()
            out[f"{name}_target"] = target.flat()
            for moment in ("exp_avg", "exp_avg_sq"):
                parts = [
                    opt.state[t][moment].reshape(self.agents, -1)
                    if t in opt.state
                    else torch.zeros_like(t).reshape(self.agents, -1)
                    for t in net.tensors
                ]
                out[f"{name}_{moment}"] = torch.cat(parts, dim=1).cpu().numpy()
        return out

    def _whole(self, what: str) -> ValueError:
        return ValueError(f"the 'autograd' learner {what}: its optimizers hold every agent's state")

    @property
    def steps(self) -> np.ndarray:
        """Per-agent Adam step counts: none (one optimizer step count for all agents)."""
        raise self._whole("has no per-agent step counts")

    def load_state(self, state: dict[str, np.ndarray], steps: np.ndarray) -> None:
        """Not possible: the optimizers' state is not per agent."""
        raise self._whole("cannot load one agent's state")

    def reset_agent(self, agent: int, theta: np.ndarray, omega: np.ndarray) -> None:
        """Not possible: the optimizers' step count is shared by every agent."""
        raise self._whole("cannot reset one agent")

    def select(self, index: list[int]) -> AutogradDDPG:
        """Not possible: the optimizers' step count is shared by every agent."""
        raise self._whole("cannot keep only some agents")
