"""A slot trainer's batch as data (:func:`to_checkpoint`; :func:`from_checkpoint` continues it):
plain data (JSON-able settings, searches, queue, stream seeds, generator state) and named CPU
tensors (networks, targets, Adam state, replay buffers, environments, counters), nothing that
names a Python class; and the batch again from them, every value checked against the layout
of a batch of its settings and slots before it is used (a missing, extra or misshapen tensor
or value raises :class:`~lonlib.util.plain_data.StateLayoutError`)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import torch

from lonlib.config import DDPGConfig, PendulumConfig
from lonlib.config.ddpg import without_default_judging
from lonlib.ddpg.devices import host_tensor, to_host
from lonlib.ddpg.learner import Learner, make_learner
from lonlib.ddpg.plain_state import TensorReader
from lonlib.ddpg.replay import ReplayBuffer
from lonlib.ddpg.slots import (
    HISTORY_COLUMNS,
    JUDGE_BATCH,
    SLOT_ARRAYS,
    EpisodeRecord,
    LocalSearchResult,
    SlotSearch,
)
from lonlib.ddpg.streams import CounterStreams
from lonlib.ddpg.trainer import SlotTrainer
from lonlib.task.pendulum import CoupledPendulums, EndReason
from lonlib.util.plain_data import (
    StateLayoutError,
    config_from_plain,
    generator_from_state,
    generator_state,
    plain_bool,
    plain_dict,
    plain_float,
    plain_int,
    plain_list,
    plain_str,
    short_repr,
)

# The plain data of SlotTrainer.to_checkpoint, and of each search in it.
CHECKPOINT_KEYS = frozenset(
    {
        "slots",
        "env",
        "ddpg",
        "judge_batch",
        "stream_seeds",
        "sim_generator",
        "history_columns",
        "searches",
        "pending",
    }
)
SEARCH_KEYS = frozenset(
    {
        "tag",
        "best",
        "started",
        "pending",
        "fitness",
        "start_fitness",
        "env_steps",
        "seconds",
        "stop_reason",
        "updates",
        "final_evaluation",
        "episodes",
    }
)
LEARNER_STATE = (
    "actor",
    "actor_target",
    "actor_exp_avg",
    "actor_exp_avg_sq",
    "critic",
    "critic_target",
    "critic_exp_avg",
    "critic_exp_avg_sq",
)
_INT_COLUMNS = [f.type in ("int", int) for f in dataclasses.fields(EpisodeRecord)]
_SCALARS = (str, int, float, bool, type(None))


def _tensor(array: np.ndarray) -> torch.Tensor:
    """A CPU tensor of its own (exactly its bytes: no larger storage is saved with it)."""
    return torch.from_numpy(np.array(array, copy=True))


def _rows(arrays: list[np.ndarray], width: int) -> torch.Tensor:
    """Flat float32 vectors stacked as ``[m, width]`` (``m`` may be zero)."""
    stacked = np.stack(arrays) if arrays else np.zeros((0, width))
    return torch.from_numpy(stacked.astype(np.float32))


def _plain_tag(tag: Any) -> Any:
    """A slot's tag as plain data: a number, text, None, or a tuple of them (as a list)."""
    if isinstance(tag, np.generic):
        tag = tag.item()
    if isinstance(tag, tuple):
        tag = [t.item() if isinstance(t, np.generic) else t for t in tag]
        if all(isinstance(t, _SCALARS) for t in tag):
            return tag
    elif isinstance(tag, _SCALARS):
        return tag
    raise ValueError(f"a checkpointed slot's tag must be plain data or a tuple of it: {tag!r}")


def _tag_from_plain(value: Any, name: str) -> Any:
    """:func:`_plain_tag` reversed (a list is a tuple)."""
    if isinstance(value, list) and all(isinstance(v, _SCALARS) for v in value):
        return tuple(value)
    if isinstance(value, _SCALARS):
        return value
    raise StateLayoutError(f"{name} must be plain data or a list of it, got {short_repr(value)}")


def _search_to_plain(search: SlotSearch) -> dict[str, Any]:
    """A search's bookkeeping but its parameters and history (tensors) as plain data."""
    result = search.result
    return {
        "tag": _plain_tag(search.tag),
        "best": [float(search.best[0]), float(search.best[1])],
        "started": float(search.started),
        "pending": int(search.pending),
        "fitness": float(result.fitness),
        "start_fitness": float(result.start_fitness),
        "env_steps": int(result.env_steps),
        "seconds": float(result.seconds),
        "stop_reason": str(result.stop_reason),
        "updates": int(result.updates),
        "final_evaluation": bool(result.final_evaluation),
        "episodes": len(result.history),
    }


def _searches_to_checkpoint(
    searches: list[SlotSearch | None],
    pending: list[tuple[SlotSearch, EpisodeRecord, np.ndarray, np.ndarray]],
    a_size: int,
    c_size: int,
) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """The slots' searches and the queued evaluations: plain data (a queued evaluation is
    its slot and the index of its episode in that search's history) and tensors."""
    held = [search for search in searches if search is not None]
    slot_of = {id(search): slot for slot, search in enumerate(searches) if search}
    queue = []
    for search, record, _, _ in pending:
        history = search.result.history
        index = next(i for i in range(len(history) - 1, -1, -1) if history[i] is record)
        queue.append([slot_of[id(search)], index])
    rows = [[getattr(r, c) for c in HISTORY_COLUMNS] for s in held for r in s.result.history]
    plain = {
        "history_columns": list(HISTORY_COLUMNS),
        "searches": [None if s is None else _search_to_plain(s) for s in searches],
        "pending": queue,
    }
    tensors = {
        "searches.theta": _rows([s.theta for s in held], a_size),
        "searches.omega": _rows([s.omega for s in held], c_size),
        "searches.best_theta": _rows([s.result.theta for s in held], a_size),
        "searches.best_omega": _rows([s.result.omega for s in held], c_size),
        "searches.history": torch.tensor(rows, dtype=torch.float64).reshape(
            -1, len(HISTORY_COLUMNS)
        ),
        "pending.theta": _rows([item[2] for item in pending], a_size),
        "pending.omega": _rows([item[3] for item in pending], c_size),
    }
    return plain, tensors


def _search_fields(entry: Any, name: str, hp: DDPGConfig) -> dict[str, Any]:
    """A search's plain data (:func:`_search_to_plain`), every value checked: counts within
    a search's budget, times finite, scores a number or ``-inf`` (none yet)."""
    entry = plain_dict(entry, name, SEARCH_KEYS)
    best = plain_list(entry["best"], f"{name}.best", 2)
    fields = {"tag": _tag_from_plain(entry["tag"], f"{name}.tag")}
    fields["best"] = tuple(_score(v, f"{name}.best") for v in best)
    fields["fitness"] = _score(entry["fitness"], f"{name}.fitness")
    for key in ("started", "start_fitness"):
        fields[key] = plain_float(entry[key], f"{name}.{key}", finite=True)
    fields["seconds"] = plain_float(entry["seconds"], f"{name}.seconds", finite=True)
    if fields["seconds"] < 0:
        raise StateLayoutError(f"{name}.seconds must be >= 0, got {fields['seconds']}")
    for key in ("pending", "env_steps", "updates", "episodes"):
        fields[key] = plain_int(entry[key], f"{name}.{key}", 0, hp.max_steps)
    fields["stop_reason"] = plain_str(entry["stop_reason"], f"{name}.stop_reason")
    if fields["stop_reason"] not in ("patience", "budget"):
        raise StateLayoutError(f"{name}.stop_reason must be 'patience' or 'budget'")
    fields["final_evaluation"] = plain_bool(entry["final_evaluation"], f"{name}.final_evaluation")
    return fields


def _score(value: Any, name: str) -> float:
    """A greedy score: a number, or ``-inf`` before the first (not NaN nor ``+inf``)."""
    score = plain_float(value, name)
    if np.isnan(score) or score == np.inf:
        raise StateLayoutError(f"{name} must be a number or -Infinity, got {score}")
    return score


def _history(rows: np.ndarray) -> list[EpisodeRecord]:
    """Episode records from ``[m, len(HISTORY_COLUMNS)]`` float64 rows."""
    ints = rows[:, _INT_COLUMNS]
    if not (np.isfinite(ints) & (ints == np.round(ints))).all():
        raise StateLayoutError("searches.history: an integer column holds a fraction")
    if (ints < 0).any():
        raise StateLayoutError("searches.history: a negative count")
    kinds: list[type[int] | type[float]] = [int if is_int else float for is_int in _INT_COLUMNS]
    # each column's kind is its field's (an int or a float)
    values: list[list[Any]] = [
        [kind(v) for kind, v in zip(kinds, row.tolist(), strict=True)] for row in rows
    ]
    return [EpisodeRecord(*row) for row in values]


def _searches_from_checkpoint(
    plain: dict[str, Any], reader: TensorReader, trainer: SlotTrainer
) -> tuple[list[SlotSearch | None], list[tuple[SlotSearch, EpisodeRecord, np.ndarray, np.ndarray]]]:
    """:func:`_searches_to_checkpoint` reversed, every value checked."""
    k = len(trainer.busy)
    a_size, c_size = trainer.a_spec.n_params, trainer.c_spec.n_params
    columns = plain_list(plain["history_columns"], "trainer.history_columns")
    if tuple(columns) != HISTORY_COLUMNS:
        raise StateLayoutError(f"trainer.history_columns: {columns}, expected {HISTORY_COLUMNS}")
    entries = plain_list(plain["searches"], "trainer.searches", k)
    fields = [
        None if entry is None else _search_fields(entry, f"trainer.searches[{slot}]", trainer.hp)
        for slot, entry in enumerate(entries)
    ]
    held = [slot for slot, entry in enumerate(fields) if entry is not None]
    arrays = {
        name: reader.take_numpy(f"searches.{name}", (len(held), size), torch.float32, True)
        for name, size in (
            ("theta", a_size),
            ("omega", c_size),
            ("best_theta", a_size),
            ("best_omega", c_size),
        )
    }
    total = sum(entry["episodes"] for entry in fields if entry is not None)
    rows = reader.take_numpy("searches.history", (total, len(HISTORY_COLUMNS)), torch.float64)
    searches: list[SlotSearch | None] = [None] * k
    offset = 0
    for j, slot in enumerate(held):
        f = fields[slot]
        assert f is not None  # a held slot's
        history = _history(rows[offset : offset + f["episodes"]])
        offset += f["episodes"]
        result = LocalSearchResult(
            fitness=f["fitness"],
            theta=arrays["best_theta"][j].copy(),
            omega=arrays["best_omega"][j].copy(),
            start_fitness=f["start_fitness"],
            env_steps=f["env_steps"],
            seconds=f["seconds"],
            stop_reason=f["stop_reason"],
            updates=f["updates"],
            final_evaluation=f["final_evaluation"],
            history=history,
        )
        theta, omega = arrays["theta"][j].copy(), arrays["omega"][j].copy()
        search = SlotSearch(f["tag"], theta, omega, result, f["best"], f["started"])
        search.pending = f["pending"]
        searches[slot] = search
    return searches, _pending_from_checkpoint(plain, reader, searches, a_size, c_size)


def _pending_from_checkpoint(
    plain: dict[str, Any],
    reader: TensorReader,
    searches: list[SlotSearch | None],
    a_size: int,
    c_size: int,
) -> list[tuple[SlotSearch, EpisodeRecord, np.ndarray, np.ndarray]]:
    """The queued evaluations: each names a slot with a search and an episode of its
    history, and every search queues as many as its count says."""
    queue = plain_list(plain["pending"], "trainer.pending")
    thetas = reader.take_numpy("pending.theta", (len(queue), a_size), torch.float32, True)
    omegas = reader.take_numpy("pending.omega", (len(queue), c_size), torch.float32, True)
    pending = []
    for i, item in enumerate(queue):
        slot, index = plain_list(item, f"trainer.pending[{i}]", 2)
        search = searches[plain_int(slot, f"trainer.pending[{i}] slot", 0, len(searches) - 1)]
        if search is None:
            raise StateLayoutError(f"trainer.pending[{i}]: slot {slot} holds no search")
        history = search.result.history
        index = plain_int(index, f"trainer.pending[{i}] episode", 0, len(history) - 1)
        pending.append((search, history[index], thetas[i], omegas[i]))
    for slot, search in enumerate(searches):
        if search is not None and search.pending != sum(item[0] is search for item in pending):
            raise StateLayoutError(f"trainer.searches[{slot}].pending: not its queued count")
    return pending


def _check_counters(trainer: SlotTrainer) -> None:
    """Refuse counters no batch of ``trainer``'s settings reaches. The ranges follow from
    :meth:`SlotTrainer.step`: a search stops at ``max_steps``; a slot updates, ends an
    episode and counts a loss at most once per env step (the losses since its last episode
    end); its patience counts from the warm-up's end or an episode end it has reached; an
    environment ends at its step limit, counts at most one upright step per step, and a busy
    slot's is reset as soon as it ends; a busy slot's search holds one record per episode."""
    hp, sim = trainer.hp, trainer.sim
    steps, busy = trainer.steps, trainer.busy
    valid = {
        "slots.steps": (steps >= 0) & (steps <= hp.max_steps),
        "slots.updates": (trainer.updates >= 0) & (trainer.updates <= steps),
        "slots.episodes": (trainer.episodes >= 0) & (trainer.episodes <= steps),
        "slots.loss_count": (trainer.loss_count >= 0) & (trainer.loss_count <= trainer.updates),
        "slots.last_improvement": (trainer.last_improvement >= 0)
        & (trainer.last_improvement <= np.maximum(steps, hp.warmup_steps)),
        "sim.step_count": (sim.step_count >= 0) & (sim.step_count <= trainer.env_config.steps),
        "sim.end_reason": np.isin(sim.end_reason, [reason.value for reason in EndReason])
        & (~busy | (sim.end_reason == EndReason.RUNNING)),
    }
    for name in ("upright_sum", "upright_all_sum", "upright_mean_sum"):
        total = getattr(sim, name)
        valid[f"sim.{name}"] = (total >= 0) & (total <= sim.step_count)
    episodes = [len(s.result.history) if s else 0 for s in trainer.searches]
    valid["trainer.searches"] = ~busy | (np.asarray(episodes) == trainer.episodes)
    for name, fits in valid.items():
        if not fits.all():
            slot = int(np.flatnonzero(~fits)[0])
            raise StateLayoutError(f"{name}: slot {slot} holds a value no search reaches")


def _learner_from_checkpoint(reader: TensorReader, trainer: SlotTrainer) -> Learner:
    """The lean learner of ``trainer``'s slots from the ``learner.*`` tensors (Eq. 1 order
    and Adam step counts)."""
    k = len(trainer.busy)
    sizes = {"actor": trainer.a_spec.n_params, "critic": trainer.c_spec.n_params}
    arrays = {
        name: reader.take_numpy(
            f"learner.{name}", (k, sizes[name.split("_")[0]]), torch.float32, finite=True
        )
        for name in LEARNER_STATE
    }
    if any((arrays[name] < 0).any() for name in ("actor_exp_avg_sq", "critic_exp_avg_sq")):
        raise StateLayoutError("learner: negative Adam second moments")
    steps = reader.take_numpy("learner.adam_steps", (k,), torch.int64)
    if (steps < 0).any():
        raise StateLayoutError("learner.adam_steps: negative step counts")
    learner = make_learner(
        trainer.a_spec,
        trainer.c_spec,
        arrays["actor"],
        arrays["critic"],
        trainer.hp,
        trainer.device,
    )
    learner.load_state(arrays, steps)
    return learner


def to_checkpoint(trainer: SlotTrainer) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """The whole batch as plain data (JSON-able: settings, searches, queue, stream seeds,
    generator state) and named CPU tensors (networks, targets, Adam state, replay buffers,
    environments, counters): nothing names a Python class. :func:`from_checkpoint`
    continues it bit for bit. Needs the lean learner."""
    if not trainer.learner.per_agent_state:
        raise ValueError(f"the {trainer.hp.update!r} learner cannot be checkpointed; use 'lean'")
    tensors = {f"slots.{name}": _tensor(getattr(trainer, name)) for name in SLOT_ARRAYS}
    tensors["slots.loss_sum"] = host_tensor(to_host(trainer.loss_sum))
    for name, array in trainer.learner.state().items():
        tensors[f"learner.{name}"] = _tensor(array)
    tensors["learner.adam_steps"] = _tensor(trainer.learner.steps)
    for name, tensor in trainer.replay.state_tensors().items():
        tensors[f"replay.{name}"] = tensor
    for name in CoupledPendulums.STATE_ARRAYS:
        tensors[f"sim.{name}"] = _tensor(getattr(trainer.sim, name))
    searches, search_tensors = _searches_to_checkpoint(
        trainer.searches, trainer.pending, trainer.a_spec.n_params, trainer.c_spec.n_params
    )
    tensors.update(search_tensors)
    plain = {
        "slots": trainer.slots,
        "env": dataclasses.asdict(trainer.env_config),
        "ddpg": without_default_judging(dataclasses.asdict(trainer.hp)),
        "judge_batch": trainer.judge_batch,
        "stream_seeds": list(trainer.streams.seeds),
        "sim_generator": generator_state(trainer.sim.rng),
        **searches,
    }
    return plain, tensors


def checkpoint_configs(plain: Any) -> tuple[PendulumConfig, DDPGConfig]:
    """The environment and DDPG settings a batch in :func:`to_checkpoint`'s ``plain``
    data was trained with (:class:`~lonlib.ddpg.plain_state.StateLayoutError` if absent or
    invalid)."""
    plain = plain_dict(plain, "trainer", CHECKPOINT_KEYS)
    env_config = config_from_plain(PendulumConfig, plain["env"], "trainer.env")
    ddpg = plain["ddpg"]
    if isinstance(ddpg, dict) and "judge_every" not in ddpg:
        # written with judge_every 0, or before the setting existed (every episode then)
        ddpg = {**ddpg, "judge_every": 0}
    return env_config, config_from_plain(DDPGConfig, ddpg, "trainer.ddpg")


def from_checkpoint(plain: Any, tensors: Any, device: str | None = None) -> SlotTrainer:
    """The batch :func:`to_checkpoint` exported, continuing bit for bit, on ``device``
    (default: the device it was trained on). Everything is checked against the layout of a
    batch of its settings and slots before it is used: a missing, extra or misshapen tensor
    or value raises :class:`~lonlib.util.plain_data.StateLayoutError`."""
    env_config, hp = checkpoint_configs(plain)
    k = plain_int(plain["slots"], "trainer.slots", 1, 100_000)
    if hp.update != "lean":
        raise StateLayoutError(f"trainer.ddpg.update must be 'lean', got {hp.update!r}")
    reader = TensorReader(tensors)
    trainer = SlotTrainer.blank(env_config, hp, k, hp.device if device is None else device)
    for name in SLOT_ARRAYS:
        array = reader.take_like(f"slots.{name}", getattr(trainer, name), finite=True)
        setattr(trainer, name, array)
    trainer.loss_sum = reader.take_like("slots.loss_sum", trainer.loss_sum)
    trainer.learner = _learner_from_checkpoint(reader, trainer)
    obs_size, n = env_config.observation_size, trainer.n
    trainer.replay = ReplayBuffer.from_state(
        reader, "replay.", k, hp.buffer_size, obs_size, n, trainer.device
    )
    seeds = plain_list(plain["stream_seeds"], "trainer.stream_seeds", k)
    try:
        trainer.streams = CounterStreams(seeds, trainer.device)
    except ValueError as error:
        raise StateLayoutError(f"trainer.stream_seeds: {error}") from None
    trainer.sim = CoupledPendulums(env_config, k)
    for name in CoupledPendulums.STATE_ARRAYS:
        array = reader.take_like(f"sim.{name}", getattr(trainer.sim, name), finite=True)
        setattr(trainer.sim, name, array)
    trainer.sim.rng = generator_from_state(plain["sim_generator"], "trainer.sim_generator")
    trainer.searches, trainer.pending = _searches_from_checkpoint(plain, reader, trainer)
    # JUDGE_BATCH is the most the constructor sets (fewer slots: as many), and a step
    # leaves fewer evaluations queued than that
    trainer.judge_batch = plain_int(plain["judge_batch"], "trainer.judge_batch", 1, JUDGE_BATCH)
    trainer.start_spread, trainer.on_judged = None, None
    if len(trainer.pending) >= trainer.judge_batch:
        raise StateLayoutError("trainer.pending: more queued than a step leaves")
    reader.finish()
    if not np.array_equal(trainer.busy, [s is not None for s in trainer.searches]):
        raise StateLayoutError("trainer: the busy slots are not the slots with a search")
    _check_counters(trainer)
    trainer.restored()
    return trainer
