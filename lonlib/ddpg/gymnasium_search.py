"""DDPG as the local search ``F(theta, omega, e, h)`` on a Gymnasium task, one agent.

The same algorithm and rules as the coupled pendulums' slot trainer
(:mod:`lonlib.ddpg.trainer`), read top to bottom for one agent and one environment; the
update is the same learner (:func:`lonlib.ddpg.learner.make_learner`, ``hp.update``) on the
task's network shapes. One environment step is:

1. act: uniform random actions in [0, 1] during the warm-up, then the Actor plus
   N(0, noise_std) noise, clipped to [0, 1]; the task maps [0, 1] onto its Box bounds;
2. step the environment; store ``(s, a, r, s', terminated)`` (a truncation bootstraps);
3. update (after the warm-up) on ``batch_size`` transitions drawn uniformly from the buffer;
4. when an episode ends: judge the trained Actor by the task's greedy episode (with
   ``hp.judge_every``, only when the episode's end crosses a multiple of it); keep the best
   (the start and warm-up policies are not candidates unless ``hp.count_start``); reset.

The search stops after ``patience_steps`` without a better greedy fitness (counted from the
end of the warm-up, never before ``min_steps``) or at ``max_steps``. Every random number
comes from a ``numpy`` generator seeded with the local search's seed (warm-up actions,
noise, replay draws, each episode's ``reset`` seed), so a search is a deterministic
function of its start, its seed and the machine's arithmetic; an interrupted one re-runs
from its start.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from lonlib.config import DDPGConfig
from lonlib.ddpg.learner import make_learner
from lonlib.ddpg.replay import ReplayBuffer
from lonlib.ddpg.slots import EpisodeRecord, LocalSearchResult, is_improvement, starting_result
from lonlib.task.gymnasium_task import GymnasiumTask


def gymnasium_local_search(
    task: GymnasiumTask,
    theta: np.ndarray,
    omega: np.ndarray,
    hp: DDPGConfig,
    seed: int,
    where: str = "local search",
) -> LocalSearchResult:
    """``F(theta, omega, e, h)`` on a Gymnasium task: DDPG from the given Actor and Critic
    (targets copied from them, an empty replay buffer); the best judged policy and its
    fitness. ``where`` names the search in an environment's error."""
    started = time.perf_counter()
    device = torch.device(hp.device)
    if device.type == "cpu":
        torch.set_num_threads(hp.threads)  # the thread count can change float reductions
    rng = np.random.default_rng([seed, 7])
    learner = make_learner(task.actor_spec, task.critic_spec, theta[None], omega[None], hp, device)
    replay = ReplayBuffer(1, hp.buffer_size, task.obs_size, task.action_size, device)
    env = task.make_env()

    def greedy(actor: np.ndarray) -> tuple[float, float]:
        episode = task.greedy_episode(actor, f"{where}, greedy episode")
        return episode.fitness, episode.episode_return

    start_score = greedy(theta)
    result = starting_result(theta, omega, start_score[0], hp.count_start)
    best = start_score if hp.count_start else (-np.inf, -np.inf)
    last_improvement = hp.warmup_steps  # the patience window opens with the first update
    episode, episode_return, episode_length, updates = 0, 0.0, 0, 0
    losses: list[tuple[float, float]] = []
    obs = task.reset(env, int(rng.integers(2**31)), where)

    for steps in range(1, hp.max_steps + 1):
        # 1. act
        if steps <= hp.warmup_steps:
            action = rng.uniform(0.0, 1.0, task.action_size)
        else:
            mu = learner.act(torch.as_tensor(obs, dtype=torch.float32, device=device)[None])
            noise = rng.standard_normal(task.action_size)
            action = np.clip(mu[0].cpu().numpy().astype(np.float64) + hp.noise_std * noise, 0, 1)
        # 2. step and store
        next_obs, reward, terminated, truncated = task.step(env, action, where, steps)
        replay.add(
            torch.as_tensor(obs, dtype=torch.float32, device=device)[None],
            torch.as_tensor(action, dtype=torch.float32, device=device)[None],
            np.array([reward]),
            next_obs[None].astype(np.float32),
            np.array([terminated]),
        )
        episode_return += reward
        episode_length += 1
        # 3. update
        if steps >= hp.warmup_steps:
            size = int(replay.size[0])
            indices = rng.integers(0, size, size=(1, hp.batch_size))
            critic_loss, actor_loss = learner.update(replay.sample(indices))
            losses.append((float(critic_loss[0]), float(actor_loss[0])))
            updates += 1
        # 4. episode end: judge, reset
        if terminated or truncated:
            previous_end = result.history[-1].env_steps if result.history else 0
            judged = (updates > 0 or hp.count_start) and (
                not hp.judge_every or steps // hp.judge_every > previous_end // hp.judge_every
            )
            record = EpisodeRecord(
                episode=episode,
                env_steps=steps,
                episode_return=episode_return,
                episode_length=episode_length,
                greedy_fitness=np.nan,
                greedy_return=np.nan,
                critic_loss=float(np.mean([c for c, _ in losses])) if losses else np.nan,
                actor_loss=float(np.mean([a for _, a in losses])) if losses else np.nan,
                seconds=time.perf_counter() - started,
            )
            if judged:
                actor = learner.actor_flat()[0] if updates else theta
                critic = learner.critic_flat()[0] if updates else omega
                score = greedy(actor)
                record.greedy_fitness, record.greedy_return = score
                if is_improvement(score, best, hp.plateau_tiebreak):
                    best = score
                    result.fitness, result.theta, result.omega = score[0], actor, critic
                    last_improvement = max(steps, hp.warmup_steps)
            result.history.append(record)
            episode, episode_return, episode_length, losses = episode + 1, 0.0, 0, []
            obs = task.reset(env, int(rng.integers(2**31)), where)
        else:
            obs = next_obs
        if steps >= hp.min_steps and steps - last_improvement >= hp.patience_steps:
            result.stop_reason = "patience"
            break

    if best[0] == -np.inf:  # no trained policy was judged: the Actor at the stop
        actor, critic = learner.actor_flat()[0], learner.critic_flat()[0]
        result.fitness, result.theta, result.omega = greedy(actor)[0], actor, critic
        result.final_evaluation = True
    result.env_steps, result.updates = steps, updates
    result.seconds = time.perf_counter() - started
    env.close()
    return result


__all__ = ["gymnasium_local_search"]
