"""DDPG as the local search ``F(theta, omega, e, h)`` of the paper, k agents at a time.

One call trains ``k`` independent agents in lockstep: each has its own environment, replay
buffer, exploration noise, sampling stream and Adam state, and all ``k`` updates run as one
batched matrix product per layer (the learner, :mod:`lonlib.ddpg_update`). ``k = 1`` is the
single-agent case of the same code. Read top to bottom, one environment step is:

1. act: uniform random actions during the warm-up, then the Actor plus N(0, sigma) noise,
   clipped to [0, 1];
2. step every agent's environment, store ``(s, a, r, s', terminated)`` in its replay buffer;
3. update (after the warm-up): sample ``batch_size`` transitions per agent, critic towards
   ``r + gamma (1 - terminated) Q'(s', mu'(s'))`` (no bootstrapping past a collision, tether
   or boundary end; the step limit bootstraps), actor up the critic's gradient, soft targets;
4. when an agent's episode ends: greedy fitness (Algorithm 1, no noise) of its current
   Actor; keep the parameters if they beat the best so far; reset its environment.

What ``F`` returns (SPEC §4): the best greedy fitness among the policies DDPG **trained**
and the parameters that scored it. The (perturbed) start is not a candidate, and neither is
any policy evaluated before the first update (during the warm-up the Actor still *is* the
start). ``count_start=True`` restores the older semantics (the start and warm-up
evaluations count as seen) for comparison. The start's fitness is always measured and
returned, with whether DDPG improved on it. A search always trains at least once
(``warmup_steps <= max_steps``); if no training episode ended after the first update, the
Actor at the stop is evaluated and returned (``final_evaluation``).

An agent stops when its greedy fitness has not improved for ``patience_steps`` environment
steps counted from the end of the warm-up (never before ``min_steps``) or at ``max_steps``.
An agent that has stopped keeps riding along in the batched update until the last one stops
(its result is frozen; the wasted work is the price of one batched matmul per layer).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from tqdm.auto import tqdm

from lonlib.ddpg_update import LEARNERS, learner_class
from lonlib.nets import NetSpec, actor_spec, critic_spec, forward_numpy
from lonlib.pendulum import CoupledPendulums, PendulumConfig, StepResult, evaluate
from lonlib.validation import check_choice, check_field_types, check_range


@dataclass(frozen=True)
class DDPGConfig:
    """DDPG hyperparameters (the paper's ``h``). Paper values: buffer, batch, noise, lr,
    gamma. Ours: tau, the warm-up and the step budget (README, "DDPG local search").

    ``plateau_tiebreak``: when the greedy fitness ties the best so far, a higher greedy
    reward return counts as progress (it keeps the parameters and resets the patience), so
    a search on a zero-fitness plateau is judged by whether it is still getting closer.

    ``count_start``: the start parameters (and greedy evaluations during the warm-up, when
    the Actor is still the start) are candidates for the returned optimum. Off by default:
    a basin-hopping trial is then accepted only if learning produced the optimum.

    ``eval_seed``: the random stream of the greedy evaluations' start noise (used only when
    the environment's ``initial_noise`` > 0). It is the same for every policy and every
    trial, so an optimum's fitness is a function of its parameters alone.

    ``device`` and ``threads`` say where the computation runs, not what it computes.

    ``update``: ``"lean"`` (:class:`lonlib.ddpg_update.LeanDDPG`, hand-written passes, the
    default) or ``"autograd"`` (:mod:`lonlib.ddpg_autograd`, the reference); same algorithm.
    """

    buffer_size: int = 40_000
    batch_size: int = 2000
    noise_std: float = 0.1
    learning_rate: float = 1e-3
    gamma: float = 0.99
    tau: float = 0.005
    warmup_steps: int = 2000
    max_steps: int = 150_000
    min_steps: int = 60_000
    patience_steps: int = 40_000
    eval_seed: int = 0
    plateau_tiebreak: bool = False
    count_start: bool = False
    device: str = "cpu"
    threads: int = 1
    update: str = "lean"

    def __post_init__(self) -> None:
        check_field_types(self)
        for name in ("buffer_size", "batch_size", "warmup_steps", "max_steps", "patience_steps"):
            check_range(name, getattr(self, name), 1)
        check_range("min_steps", self.min_steps, 0)
        check_range("threads", self.threads, 1, 256)
        check_range("noise_std", self.noise_std, 0.0, 1.0)
        check_range("learning_rate", self.learning_rate, 0.0, 1.0, low_open=True)
        check_range("gamma", self.gamma, 0.0, 1.0)
        check_range("tau", self.tau, 0.0, 1.0, low_open=True)
        if self.warmup_steps > self.max_steps:
            raise ValueError(
                f"warmup_steps must be <= max_steps ({self.max_steps}) so that DDPG trains "
                f"at least once, got {self.warmup_steps!r}"
            )
        check_choice("update", self.update, LEARNERS)
        if self.min_steps > self.max_steps:
            raise ValueError(
                f"min_steps must be <= max_steps ({self.max_steps}), got {self.min_steps!r}"
            )
        try:
            torch.device(self.device)
        except RuntimeError as error:
            raise ValueError(f"device {self.device!r} is not a torch device: {error}") from None


@dataclass
class EpisodeRecord:
    """One training episode of one agent."""

    episode: int
    env_steps: int  # the agent's environment steps when the episode ended
    episode_return: float
    episode_length: int
    greedy_fitness: float
    greedy_return: float  # the greedy episode's reward sum (the plateau tie-breaker)
    critic_loss: float  # mean over the episode's updates (nan before the warm-up ends)
    actor_loss: float
    seconds: float  # since the local search started


@dataclass
class LocalSearchResult:
    """What ``F(theta, omega, e, h)`` returns for one agent."""

    fitness: float
    theta: np.ndarray  # Actor parameters at the best greedy fitness, float32 [P_actor]
    omega: np.ndarray  # Critic parameters at that point, float32 [P_critic]
    start_fitness: float  # greedy fitness of the (perturbed) start parameters
    env_steps: int
    seconds: float
    stop_reason: str  # "patience" or "budget"
    updates: int = 0  # DDPG updates of this agent
    final_evaluation: bool = False  # no training episode ended after the first update
    history: list[EpisodeRecord] = field(default_factory=list)

    @property
    def improved(self) -> bool:
        """Did DDPG return something strictly fitter than its start?"""
        return self.fitness > self.start_fitness


def is_improvement(
    candidate: tuple[float, float], incumbent: tuple[float, float], plateau_tiebreak: bool
) -> bool:
    """Does a greedy ``(fitness, return)`` beat the best so far? Higher fitness always does;
    with ``plateau_tiebreak``, equal fitness and a higher reward return does too."""
    if candidate[0] != incumbent[0] or not plateau_tiebreak:
        return candidate[0] > incumbent[0]
    return candidate[1] > incumbent[1] + 1e-9


def check_parameters(name: str, values: np.ndarray, size: int, agents: int) -> np.ndarray:
    """Validate flat parameter vectors ``[k, size]`` (finite, right shape) and return float32."""
    values = np.asarray(values, dtype=np.float32)
    if values.ndim == 1:
        values = values[None]
    if values.shape != (agents, size):
        raise ValueError(f"{name} must have shape ({agents}, {size}), got {values.shape}")
    if not np.isfinite(values).all():
        raise ValueError(f"{name} contains NaN or infinite parameters")
    return values


def local_search(
    theta: np.ndarray,
    omega: np.ndarray,
    env_config: PendulumConfig,
    hp: DDPGConfig,
    seed: int,
    progress: bool = False,
) -> LocalSearchResult:
    """``F(theta, omega, e, h)`` for one agent: DDPG from the given Actor and Critic."""
    return local_search_batch(theta[None], omega[None], env_config, hp, [seed], progress)[0]


def local_search_batch(
    thetas: np.ndarray,
    omegas: np.ndarray,
    env_config: PendulumConfig,
    hp: DDPGConfig,
    seeds: Sequence[int],
    progress: bool = False,
) -> list[LocalSearchResult]:
    """Train ``k = len(seeds)`` independent agents together; one result per agent.

    Agent ``i`` starts from ``thetas[i]``, ``omegas[i]`` with an empty replay buffer and
    target networks copied from them, and draws every random number of its training
    (warm-up actions, exploration noise, replay sampling, episode start noise) from
    ``np.random.default_rng(seeds[i])``: its result does not depend on the other agents.
    """
    k = len(seeds)
    n = env_config.n_carts
    a_spec, c_spec = actor_spec(n), critic_spec(n)
    thetas = check_parameters("theta", thetas, a_spec.n_params, k)
    omegas = check_parameters("omega", omegas, c_spec.n_params, k)
    torch.set_num_threads(hp.threads)
    device = torch.device(hp.device)
    rngs = [np.random.default_rng(seed) for seed in seeds]
    start_time = time.perf_counter()

    learner = make_learner(a_spec, c_spec, thetas, omegas, hp)
    replay = ReplayBuffer(k, hp.buffer_size, env_config.observation_size, n, device)

    def greedy(flat_theta: np.ndarray) -> tuple[float, float]:
        """Greedy (noise-free) fitness and reward return of one Actor."""
        return greedy_score(a_spec, flat_theta, env_config, hp.eval_seed)

    start_scores = [greedy(thetas[i]) for i in range(k)]
    no_candidate = (-np.inf, -np.inf)
    scores = list(start_scores) if hp.count_start else [no_candidate] * k
    results = [
        LocalSearchResult(
            fitness=start_scores[i][0] if hp.count_start else -np.inf,
            theta=thetas[i].copy(),
            omega=omegas[i].copy(),
            start_fitness=start_scores[i][0],
            env_steps=0,
            seconds=0.0,
            stop_reason="budget",
        )
        for i in range(k)
    ]
    # The patience window opens when training starts (the first update).
    last_improvement = np.full(k, hp.warmup_steps, dtype=np.int64)
    active = np.ones(k, dtype=bool)

    sim = CoupledPendulums(env_config, k)
    _reset(sim, rngs, np.ones(k, dtype=bool))
    obs = sim.observe().astype(np.float32)
    episode_return = np.zeros(k)
    episode_index = np.zeros(k, dtype=np.int64)
    losses: list[list[tuple[float, float]]] = [[] for _ in range(k)]

    bar = tqdm(total=hp.max_steps, desc=f"DDPG x{k}", disable=not progress, leave=False)
    step = updates = 0
    while active.any():
        # 1. act
        if step < hp.warmup_steps:
            actions = np.stack([rng.uniform(0.0, 1.0, n) for rng in rngs])
        else:
            mu = learner.act(torch.as_tensor(obs, device=device))
            actions = exploration_actions(mu.cpu().numpy().astype(np.float64), rngs, hp.noise_std)
        # 2. step and store
        outcome = sim.step(actions)
        next_obs = sim.observe().astype(np.float32)
        replay.add_step(obs, actions, outcome, next_obs)
        episode_return += outcome.reward
        step += 1
        # 3. update
        if step >= hp.warmup_steps:
            indices = np.stack([rng.integers(0, replay.size, hp.batch_size) for rng in rngs])
            critic_loss, actor_loss = learner.update(replay.sample(indices))
            updates += 1
            for i in np.flatnonzero(active):
                losses[i].append((critic_loss[i], actor_loss[i]))
        # 4. episode ends: greedy fitness of trained policies, best parameters, reset
        ended = outcome.terminated | outcome.truncated
        if ended.any():
            candidate = hp.count_start or updates > 0
            flat_actor = learner.actor_flat()
            flat_critic = learner.critic_flat() if (ended & active).any() and candidate else None
            for i in np.flatnonzero(ended & active):
                score = greedy(flat_actor[i]) if candidate else (np.nan, np.nan)
                if candidate and is_improvement(score, scores[i], hp.plateau_tiebreak):
                    scores[i] = score
                    results[i].fitness = score[0]
                    results[i].theta = flat_actor[i].copy()
                    results[i].omega = flat_critic[i].copy()
                    last_improvement[i] = step
                episode_losses = np.array(losses[i]) if losses[i] else np.full((1, 2), np.nan)
                results[i].history.append(
                    EpisodeRecord(
                        episode=int(episode_index[i]),
                        env_steps=step,
                        episode_return=float(episode_return[i]),
                        episode_length=int(sim.step_count[i]),
                        greedy_fitness=score[0],
                        greedy_return=score[1],
                        critic_loss=float(np.mean(episode_losses[:, 0])),
                        actor_loss=float(np.mean(episode_losses[:, 1])),
                        seconds=time.perf_counter() - start_time,
                    )
                )
                losses[i] = []
            episode_index[ended] += 1
            episode_return[ended] = 0.0
            _reset(sim, rngs, ended)
            obs = sim.observe().astype(np.float32)
        else:
            obs = next_obs
        # stopping rules
        stale = (step >= hp.min_steps) & (step - last_improvement >= hp.patience_steps)
        stop = active & (stale | (step >= hp.max_steps))
        if stop.any():
            flat_actor, flat_critic = learner.actor_flat(), learner.critic_flat()
        for i in np.flatnonzero(stop):
            if scores[i] is no_candidate:  # no training episode ended: judge the Actor now
                scores[i] = greedy(flat_actor[i])
                results[i].fitness = scores[i][0]
                results[i].theta = flat_actor[i].copy()
                results[i].omega = flat_critic[i].copy()
                results[i].final_evaluation = True
            results[i].stop_reason = "patience" if stale[i] else "budget"
            results[i].env_steps = step
            results[i].updates = updates
            results[i].seconds = time.perf_counter() - start_time
        active &= ~stop
        if progress and step % 500 == 0:
            bar.update(500)
            bar.set_postfix(best=f"{max(r.fitness for r in results):.3f}", active=int(active.sum()))
    bar.close()
    return results


def make_learner(
    a_spec: NetSpec, c_spec: NetSpec, thetas: np.ndarray, omegas: np.ndarray, hp: DDPGConfig
):
    """The learner ``hp.update`` names for ``k`` agents starting from ``thetas``, ``omegas``
    (targets copied from them, Adam state empty) on ``hp.device``."""
    return learner_class(hp.update)(
        a_spec,
        c_spec,
        thetas,
        omegas,
        learning_rate=hp.learning_rate,
        gamma=hp.gamma,
        tau=hp.tau,
        device=torch.device(hp.device),
    )


def exploration_actions(
    mu: np.ndarray, rngs: Sequence[np.random.Generator], noise_std: float
) -> np.ndarray:
    """The Actor's actions ``mu [k, n]`` plus N(0, noise_std) noise (a standard deviation)
    from each agent's own stream, clipped to the action range [0, 1]."""
    noise = np.stack([rng.normal(0.0, noise_std, mu.shape[1]) for rng in rngs])
    return np.clip(mu + noise, 0.0, 1.0)


def greedy_score(
    spec: NetSpec, flat_theta: np.ndarray, env_config: PendulumConfig, eval_seed: int
) -> tuple[float, float]:
    """Greedy (noise-free) fitness (Algorithm 1) and reward return of one flat Actor."""
    policy = lambda obs: forward_numpy(spec, flat_theta, obs)  # noqa: E731
    result = evaluate(policy, env_config, 1, eval_seed)
    return float(result.fitness[0]), float(result.episode_return[0])


def _reset(sim: CoupledPendulums, rngs: list[np.random.Generator], mask: np.ndarray) -> None:
    """Reset the masked environments, each drawing its start noise from its agent's stream."""
    noise_level = sim.config.initial_noise
    noise = None
    if noise_level > 0:
        noise = np.stack(
            [
                rngs[i].uniform(-noise_level, noise_level, size=(4, sim.config.n_carts))
                for i in np.flatnonzero(mask)
            ],
            axis=1,
        )
    sim.reset(mask, noise)


class ReplayBuffer:
    """``k`` ring buffers of transitions in one torch tensor ``[k, capacity, width]``.

    A row packs ``(s, a, r, s', 1 - terminated)``, so a sample is one ``index_select`` per
    batch instead of one gather per field. All agents step together, so one write position
    and one size serve every agent.
    """

    def __init__(
        self, agents: int, capacity: int, obs_size: int, act_size: int, device: torch.device
    ) -> None:
        self.obs_size, self.act_size = obs_size, act_size
        width = 2 * obs_size + act_size + 2
        self.data = torch.zeros(agents, capacity, width, device=device)
        self.capacity, self.position, self.size = capacity, 0, 0
        self.device = device
        self._row = np.zeros((agents, width), dtype=np.float32)
        self._offsets = torch.arange(agents, device=device)[:, None] * capacity

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
        """Store one transition per agent (arrays with a leading agent dimension)."""
        o, a = self.obs_size, self.act_size
        row = self._row
        row[:, :o] = obs
        row[:, o : o + a] = actions
        row[:, o + a] = rewards
        row[:, o + a + 1 : 2 * o + a + 1] = next_obs
        row[:, -1] = ~terminated
        self.data[:, self.position] = torch.from_numpy(row)
        self.position = (self.position + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, indices: np.ndarray) -> tuple[torch.Tensor, ...]:
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
