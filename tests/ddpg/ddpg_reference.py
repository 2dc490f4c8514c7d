"""A textbook single-agent DDPG update (CleanRL's, written out with plain torch tensors) and
an adapter that runs lonlib's batched learner on flat parameters, for the update tests."""

from __future__ import annotations

import numpy as np
import torch

from lonlib.config import DDPGConfig
from lonlib.ddpg.learner import make_learner
from lonlib.task.policy import NetSpec


def _mlp(spec: NetSpec, params: list[torch.Tensor], x: torch.Tensor) -> torch.Tensor:
    layers = len(spec.layers)
    for i in range(layers):
        x = x @ params[2 * i].T + params[2 * i + 1]
        if i < layers - 1 or spec.sigmoid_output:
            x = torch.sigmoid(x)
    return x


def _tensors(spec: NetSpec, flat: np.ndarray) -> list[torch.Tensor]:
    out = []
    for weight, bias in spec.unflatten(np.asarray(flat, dtype=np.float64)):
        out += [torch.tensor(weight, requires_grad=True), torch.tensor(bias, requires_grad=True)]
    return out


def _flat(params: list[torch.Tensor]) -> np.ndarray:
    return torch.cat([p.detach().reshape(-1) for p in params]).numpy()


def reference_updates(a_spec, c_spec, theta, omega, batches, hp: DDPGConfig) -> dict:
    """One agent, ``len(batches)`` updates, float64: critic to r + gamma * not_done *
    Q'(s', mu'(s')), actor up Q(s, mu(s)) through the updated critic, soft targets."""
    actor, critic = _tensors(a_spec, theta), _tensors(c_spec, omega)
    actor_t = [p.detach().clone() for p in actor]
    critic_t = [p.detach().clone() for p in critic]
    actor_opt = torch.optim.Adam(actor, lr=hp.learning_rate, foreach=False)
    critic_opt = torch.optim.Adam(critic, lr=hp.learning_rate, foreach=False)
    losses = []
    for obs, act, rew, next_obs, not_done in (
        [torch.tensor(np.asarray(x, dtype=np.float64)) for x in b] for b in batches
    ):
        with torch.no_grad():
            next_q = _mlp(
                c_spec, critic_t, torch.cat([next_obs, _mlp(a_spec, actor_t, next_obs)], 1)
            )
            target = rew + hp.gamma * not_done * next_q
        critic_loss = ((_mlp(c_spec, critic, torch.cat([obs, act], 1)) - target) ** 2).mean()
        critic_opt.zero_grad()
        critic_loss.backward()
        critic_opt.step()
        actor_loss = -_mlp(c_spec, critic, torch.cat([obs, _mlp(a_spec, actor, obs)], 1)).mean()
        actor_opt.zero_grad()
        actor_loss.backward()
        actor_opt.step()
        with torch.no_grad():
            for net, target_net in ((actor, actor_t), (critic, critic_t)):
                for p, t in zip(net, target_net, strict=True):
                    t.mul_(1 - hp.tau).add_(hp.tau * p)
        losses.append((critic_loss.item(), actor_loss.item()))
    return {
        "theta": _flat(actor),
        "omega": _flat(critic),
        "theta_target": _flat(actor_t),
        "omega_target": _flat(critic_t),
        "losses": np.array(losses),
    }


def lonlib_updates(a_spec, c_spec, thetas, omegas, batches, hp: DDPGConfig) -> dict:
    """k agents (flat ``[k, P]`` parameters) through lonlib's learner ``hp.update`` (the lean
    one by default); ``batches`` hold ``[k, B, ...]`` arrays ``(s, a, r, s', not_done)``."""
    learner = make_learner(a_spec, c_spec, thetas, omegas, hp)
    losses = []
    for batch in batches:
        tensors = tuple(torch.as_tensor(np.asarray(x, dtype=np.float32)) for x in batch)
        losses.append(learner.update(tensors))
    state = learner.state()
    return {
        "theta": state["actor"],
        "omega": state["critic"],
        "theta_target": state["actor_target"],
        "omega_target": state["critic_target"],
        "losses": np.array(losses).transpose(2, 0, 1),  # [k, updates, (critic, actor)]
    }
