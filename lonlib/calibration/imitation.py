"""A two-cart balancing Actor of the paper's shape, built by imitation (DAgger).

The hold test (issue 46, ``docs/study-geometry.md``) asks whether DDPG keeps the top of the
two-cart landscape once it is there, so it needs a start at the top: an Actor of the paper's
shape (``[20, 20, 20, 20, 2]``, sigmoid on every layer) that balances both rods. DDPG has not
found one; this module makes one by imitating a policy that does.

**The teacher** (:func:`pair_teacher`) is a one-cart optimum of ``data/one-cart/`` copied to
both carts. Each copy reads its own cart's ten sensors, except that the inner proximity
sensor (the one facing the neighbour) is replaced by the pair's *other* outer sensor: the left
cart's copy reads the right cart's right-hand track-end sensor in its right-hand slot, the
right cart's copy reads the left cart's left-hand one. From the symmetric nominal start both
copies then see what the one-cart optimum saw on its own track (for two carts the track is
0.55 m longer on each side and the carts start 0.55 m from the centre, so each outer end is as
far as on one cart): both act alike, the pair moves as one cart and scores the one-cart
optimum's fitness (measured: every stored one-cart optimum >= 0.976 scores the same on two
carts). Read with only its own cart's sensors (the inner one included, or the outer one in
both slots) a copy ends the episode early (the tether tightens or the carts collide, within
the first 50 steps from the nominal start): a cart moving away from its own track end no
longer sees the end it moves towards.

**The student** is trained by DAgger (Ross et al. 2011): the teacher's episodes first, then
repeatedly the student's own episodes from the nominal and from perturbed starts, every
visited state labelled with the teacher's action, the data aggregated and the student trained
further on all of it (binary cross-entropy of its output against the teacher's action, Adam).
After every round the student is scored through the one rollout
(:func:`lonlib.task.rollout.run_actors`, nominal start); the best round's Actor is returned.
Everything is seeded (``torch`` on one thread): the same configuration gives the same Actor
on the same machine; the committed Actor's fitness replays from its stored parameters on any.
"""

from __future__ import annotations

import dataclasses
import io
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lonlib.config import PendulumConfig, Scoring
from lonlib.config.pendulum import SENSORS_PER_CART
from lonlib.storage.atomic import atomic_write, write_json
from lonlib.storage.digests import reseal_files_if_sealed
from lonlib.task.policy import actor_spec, forward_numpy
from lonlib.task.rollout import (
    Policy,
    nominal_offsets,
    perturbed_offsets,
    run_actors,
    run_policy,
    score_actors,
)
from lonlib.util.validation import check_field_types, check_range

# The committed teacher: a one-cart optimum labelled "balancing" (0.977, upright from step 47).
DEFAULT_TEACHER = "data/one-cart/p=0.0001/run_0006/optimum_0007.npz"
LEFT, RIGHT = 4, 5  # the proximity sensors' places among a cart's ten


@dataclass(frozen=True)
class ImitationConfig:
    """How the imitation Actor is made (every value is stored with it)."""

    teacher: str = DEFAULT_TEACHER
    """A one-cart optimum (``.npz`` with ``theta``), copied to both carts."""
    seed: int = 0
    """Seeds torch's initialisation and shuffling and the perturbed starts."""
    rounds: int = 8
    """DAgger rounds after the teacher's own episodes."""
    starts: int = 16
    """Perturbed starts per round (beside the nominal start)."""
    noise: float = 0.02
    """Half-width of the starts' uniform perturbation (x, x_dot, phi, phi_dot)."""
    updates: int = 20_000
    """Adam steps per round (minibatches drawn in a seeded order from all the data)."""
    batch_size: int = 256
    learning_rate: float = 1e-3
    max_rows: int = 400_000
    """At most this many labelled states are kept (a seeded subsample beyond)."""

    def __post_init__(self) -> None:
        check_field_types(self)
        check_range("seed", self.seed, 0, 2**63 - 1)
        check_range("rounds", self.rounds, 0, 1000)
        check_range("starts", self.starts, 1, 100_000)
        check_range("noise", self.noise, 0.0, 0.5)
        check_range("updates", self.updates, 1, 10_000_000)
        check_range("batch_size", self.batch_size, 1, 10_000_000)
        check_range("learning_rate", self.learning_rate, 0.0, 1.0, low_open=True)
        check_range("max_rows", self.max_rows, 1)


@dataclass
class ImitationResult:
    """The best round's Actor (float32, Eq. 1 order) and what every round scored."""

    theta: np.ndarray
    fitness: float
    round: int
    teacher_fitness: float
    rounds: list[dict[str, Any]] = field(default_factory=list)


def load_teacher(path: str | Path) -> np.ndarray:
    """The one-cart Actor stored in ``path`` (an optimum's ``.npz``)."""
    with np.load(Path(path)) as data:
        theta = np.asarray(data["theta"], dtype=np.float32)
    if theta.shape != (actor_spec(1).n_params,):
        raise ValueError(
            f"{path}: a one-cart Actor has {actor_spec(1).n_params} parameters, got {theta.shape}"
        )
    return theta


def pair_inputs(observation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What each cart's copy of a one-cart Actor reads from a two-cart observation
    ``[B, 20]``: its own ten sensors with the inner proximity sensor replaced by the pair's
    other outer one (module docstring)."""
    s = SENSORS_PER_CART
    left = np.array(observation[:, :s], dtype=np.float64)
    right = np.array(observation[:, s : 2 * s], dtype=np.float64)
    left[:, RIGHT] = observation[:, s + RIGHT]
    right[:, LEFT] = observation[:, LEFT]
    return left, right


def pair_teacher(theta_one: np.ndarray, config: PendulumConfig) -> Policy:
    """The two-cart policy of a one-cart Actor copied to both carts (module docstring)."""
    if config.n_carts != 2:
        raise ValueError(f"the pair teacher drives two carts, got n_carts={config.n_carts}")
    spec = actor_spec(1)

    def policy(observation: np.ndarray) -> np.ndarray:
        left, right = pair_inputs(observation)
        return np.concatenate(
            [forward_numpy(spec, theta_one, left), forward_numpy(spec, theta_one, right)], axis=1
        )

    return policy


class _Student(torch.nn.Module):
    """The paper's Actor as a torch module that returns the output layer's logits."""

    def __init__(self, sizes: tuple[int, ...]) -> None:
        super().__init__()
        self.layers = torch.nn.ModuleList(
            torch.nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:], strict=True)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for layer in self.layers[:-1]:
            x = torch.sigmoid(layer(x))
        return self.layers[-1](x)

    def flat(self) -> np.ndarray:
        """The parameters in Eq. 1 order (weights ``[out, in]`` row-major, then biases)."""
        parts = []
        for layer in self.layers:
            parts += [layer.weight.detach().reshape(-1), layer.bias.detach()]
        return torch.cat(parts).numpy().astype(np.float32)


def _visited(rollout, rows: int) -> np.ndarray:
    """The observations of every executed step of the first ``rows`` episodes ``[N, 20]``."""
    sensors = rollout.trace.sensors
    return np.concatenate([sensors[: rollout.end_step[b], b] for b in range(rows)])


def imitate(config: ImitationConfig = ImitationConfig(), progress: bool = False) -> ImitationResult:
    """Train the two-cart Actor by DAgger of :func:`pair_teacher` (module docstring)."""
    env = PendulumConfig()
    torch.set_num_threads(1)
    torch.manual_seed(config.seed)
    shuffle = torch.Generator().manual_seed(config.seed)
    rng = np.random.default_rng([config.seed, 1])
    teacher_theta = load_teacher(config.teacher)
    teacher = pair_teacher(teacher_theta, env)
    spec = actor_spec(env.n_carts)
    student = _Student(spec.sizes)
    optimiser = torch.optim.Adam(student.parameters(), lr=config.learning_rate)

    def starts(round_index: int) -> np.ndarray:
        seed = int(np.random.SeedSequence([config.seed, 2, round_index]).generate_state(1)[0])
        perturbed = perturbed_offsets(env, config.starts, config.noise, seed=seed)
        return np.concatenate([nominal_offsets(env), perturbed], axis=1)

    first = run_policy(teacher, env, starts(0), trace=True)
    teacher_fitness = float(first.fitness[0])
    observations = _visited(first, first.end_step.shape[0])
    best: ImitationResult | None = None
    history = []
    for round_index in range(config.rounds + 1):
        if len(observations) > config.max_rows:
            keep = np.sort(rng.choice(len(observations), config.max_rows, replace=False))
            observations = observations[keep]
        inputs = torch.from_numpy(observations.astype(np.float32))
        targets = torch.from_numpy(teacher(observations).astype(np.float32))
        clock = time.perf_counter()
        done = 0
        while done < config.updates:
            order = torch.randperm(len(inputs), generator=shuffle)
            for batch in order.split(config.batch_size)[: config.updates - done]:
                loss = torch.nn.functional.binary_cross_entropy_with_logits(
                    student(inputs[batch]), targets[batch]
                )
                optimiser.zero_grad()
                loss.backward()
                optimiser.step()
                done += 1
        theta = student.flat()
        scored = score_actors(theta, env, Scoring(starts=16, noise=0.01), conditioning=True)
        fitness = float(scored.fitness[0])
        row = {
            "round": round_index,
            "rows": len(inputs),
            "loss": float(loss.detach()),
            "fitness": fitness,
            "robust_mean": float(scored.robust_mean[0]),
            "robust_min": float(scored.robust_min[0]),
            "seconds": round(time.perf_counter() - clock, 1),
        }
        history.append(row)
        if progress:
            print(f"imitation round {round_index}: {row}", flush=True)
        if best is None or fitness > best.fitness:
            best = ImitationResult(theta, fitness, round_index, teacher_fitness)
        if round_index == config.rounds:
            break
        visited = run_actors(theta, env, starts(round_index + 1), trace=True)
        observations = np.concatenate([observations, _visited(visited, visited.end_step.shape[0])])
    assert best is not None
    best.rounds = history
    return best


def write_imitation(out: str | Path, result: ImitationResult, config: ImitationConfig) -> Path:
    """Store the Actor (``actor.npy``, float32) and ``actor.json`` (its fitness through
    :func:`lonlib.task.rollout.run_actors`, the configuration and every round) in ``out``;
    the JSON is the commit point. Returns the JSON's path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    np.save(buffer, result.theta.astype(np.float32))
    atomic_write(out / "actor.npy", buffer.getvalue())
    replay = run_actors(result.theta, PendulumConfig())
    record = {
        "what": "two-cart Actor [20, 20, 20, 20, 2], sigmoid everywhere, trained by DAgger of "
        "a one-cart optimum copied to both carts (lonlib.calibration.imitation)",
        "command": f"lonlib imitate {out} --seed {config.seed}",
        "config": dataclasses.asdict(config),
        "env": dataclasses.asdict(PendulumConfig()),
        "fitness": float(replay.fitness[0]),
        "fitness_all": float(replay.fitness_all[0]),
        "fitness_mean": float(replay.fitness_mean[0]),
        "end_reason": replay.end_reason_name(0),
        "end_step": int(replay.end_step[0]),
        "teacher_fitness": result.teacher_fitness,
        "best_round": result.round,
        "rounds": result.rounds,
        "torch": torch.__version__,
    }
    if record["fitness"] != result.fitness:
        raise RuntimeError("the stored Actor does not replay the fitness it was chosen by")
    path = out / "actor.json"
    write_json(path, record)
    reseal_files_if_sealed(out)
    return path


def load_imitation(folder: str | Path) -> tuple[np.ndarray, dict[str, Any]]:
    """The stored imitation Actor and its record (:func:`write_imitation`)."""
    folder = Path(folder)
    theta = np.load(folder / "actor.npy")
    record = json.loads((folder / "actor.json").read_text())
    if theta.dtype != np.float32 or theta.shape != (actor_spec(2).n_params,):
        raise ValueError(f"{folder / 'actor.npy'}: not a two-cart Actor ({theta.shape})")
    return theta, record


__all__ = [
    "DEFAULT_TEACHER",
    "ImitationConfig",
    "ImitationResult",
    "imitate",
    "load_imitation",
    "load_teacher",
    "pair_inputs",
    "pair_teacher",
    "write_imitation",
]
