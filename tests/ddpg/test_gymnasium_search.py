"""lonlib's DDPG on a Gymnasium task (``lonlib.ddpg.gymnasium_search``): it learns, it keeps
the slot trainer's rules of what it returns, and it is a deterministic function of its start
and seed."""

import dataclasses

import gymnasium
import numpy as np
import pytest

from lonlib.config import DDPGConfig, GymnasiumTaskConfig
from lonlib.ddpg.gymnasium_search import (
    GymnasiumSlotTrainer,
    SlotEnvironmentError,
    gymnasium_local_search,
)
from lonlib.task import GymnasiumTask
from tests.task.test_gymnasium_task import Line  # registers lonlib-test/Line-v0

PENDULUM = GymnasiumTask(GymnasiumTaskConfig("Pendulum-v1", (-3254.72, 0.0)))


def start(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return PENDULUM.actor_spec.initial(rng), PENDULUM.critic_spec.initial(rng)


def test_it_learns_to_swing_up_and_hold_pendulum_v1():
    """From a random start (fitness ~0.68, the pendulum never up) DDPG balances within 12k
    env steps (measured: first >= 0.95 after ~9k)."""
    theta, omega = start()
    hp = DDPGConfig(
        batch_size=256,
        buffer_size=50_000,
        warmup_steps=1000,
        max_steps=12_000,
        min_steps=12_000,
        patience_steps=12_000,
    )
    result = gymnasium_local_search(PENDULUM, theta, omega, hp, seed=5)
    assert result.start_fitness < 0.75 and result.fitness > 0.95
    # what it returns is what its Actor scores, by the one fitness function
    assert PENDULUM.fitness(result.theta[None])[0] == result.fitness


def test_the_start_is_no_candidate_and_the_search_is_deterministic():
    theta, omega = start(1)
    hp = DDPGConfig(
        batch_size=16,
        buffer_size=500,
        warmup_steps=300,
        max_steps=800,
        min_steps=0,
        patience_steps=10_000,
    )
    one = gymnasium_local_search(PENDULUM, theta, omega, hp, seed=3)
    two = gymnasium_local_search(PENDULUM, theta, omega, hp, seed=3)
    assert np.array_equal(one.theta, two.theta) and one.fitness == two.fitness
    judged = [r.greedy_fitness for r in one.history if not np.isnan(r.greedy_fitness)]
    assert one.fitness == max(judged)  # the best judged trained policy, not the start
    # the first episode (200 steps) ends in the warm-up: its policy is the start, not judged
    assert one.history[0].env_steps == 200 and np.isnan(one.history[0].greedy_fitness)
    counted = gymnasium_local_search(
        PENDULUM, theta, omega, DDPGConfig(**{**hp.__dict__, "count_start": True}), seed=3
    )
    assert counted.fitness >= counted.start_fitness


SHORT = GymnasiumTask(GymnasiumTaskConfig("Pendulum-v1", (-3254.72, 0.0), episode_steps=40))
BATCHED = DDPGConfig(
    batch_size=16, buffer_size=400, warmup_steps=80, max_steps=480, min_steps=0, patience_steps=120
)


def short_start(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return SHORT.actor_spec.initial(rng), SHORT.critic_spec.initial(rng)


def assert_same_search(one, two):
    assert np.array_equal(one.theta, two.theta) and np.array_equal(one.omega, two.omega)
    assert (one.fitness, one.start_fitness, one.env_steps, one.updates, one.stop_reason) == (
        two.fitness,
        two.start_fitness,
        two.env_steps,
        two.updates,
        two.stop_reason,
    )
    strip = [{**vars(r), "seconds": 0} for r in one.history]
    assert str(strip) == str([{**vars(r), "seconds": 0} for r in two.history])


def test_a_batch_of_searches_is_bit_for_bit_each_search_alone():
    """Three searches through one batch of two slots: the third refills the slot the first
    frees while the second is mid-training, and the batch sheds the free slot when the
    second ends. Each returns exactly what it returns alone (own generator, own fresh
    environment, no reduction mixing agents)."""
    from tests.task.test_gymnasium_task import Line  # noqa: F401 (registers Line-v0)

    task = GymnasiumTask(GymnasiumTaskConfig("lonlib-test/Line-v0", (-200.0, 0.0)))
    hp = dataclasses.replace(BATCHED, warmup_steps=40, max_steps=600, patience_steps=100)
    seeds = [0, 3, 2]  # alone they stop after 140, 260 and 220 env steps

    def begin(seed):
        rng = np.random.default_rng(seed)
        return task.actor_spec.initial(rng)[None], task.critic_spec.initial(rng)[None]

    alone = [gymnasium_local_search(task, begin(s)[0][0], begin(s)[1][0], hp, s) for s in seeds]
    assert [r.env_steps for r in alone] == [140, 260, 220]
    first, second = begin(seeds[0]), begin(seeds[1])
    trainer = GymnasiumSlotTrainer(
        task,
        np.concatenate([first[0], second[0]]),
        np.concatenate([first[1], second[1]]),
        seeds[:2],
        hp,
        tags=["a", "b"],
    )
    assert trainer.vector.num_envs == 2  # the training environments: one vector env
    got = {}
    while trainer.busy.any():
        for tag, result in trainer.step():
            got[tag] = result
            if tag == "a":
                trainer.start(trainer.free_slots(), *begin(seeds[2]), [seeds[2]], ["c"])
            else:
                trainer.shrink()
    assert trainer.slots == 1 and trainer.vector.num_envs == 1
    for tag, result in zip("abc", alone, strict=True):
        assert_same_search(got[tag], result)


def test_a_search_comes_out_as_it_did_when_the_worked_examples_were_sampled():
    """A golden digest of one small search (its returned Actor, fitness, steps and episode
    history): lonlib's Gymnasium DDPG gives the bits it gave before the batched trainer
    replaced the one-agent loop (the committed worked examples resume on it)."""
    import hashlib

    theta, omega = short_start(7)
    result = gymnasium_local_search(SHORT, theta, omega, BATCHED, seed=11)
    digest = hashlib.sha256(result.theta.tobytes() + result.omega.tobytes()).hexdigest()
    assert (result.env_steps, result.stop_reason) == GOLDEN[:2]
    assert result.fitness == GOLDEN[2] and digest == GOLDEN[3]
    # and its per-episode history (stored with every optimum), every number but the seconds
    history = np.array(
        [[getattr(record, name) for name in HISTORY_FIELDS] for record in result.history],
        dtype=np.float64,
    )
    assert len(result.history) == 5
    assert hashlib.sha256(history.tobytes()).hexdigest() == GOLDEN_HISTORY


HISTORY_FIELDS = (
    "episode",
    "env_steps",
    "episode_return",
    "episode_length",
    "greedy_fitness",
    "greedy_return",
    "critic_loss",
    "actor_loss",
)


def test_a_failing_environment_in_a_batch_names_its_search():
    from tests.task.test_gymnasium_task import Line  # noqa: F401 (registers Line-v0)

    task = GymnasiumTask(GymnasiumTaskConfig("lonlib-test/Line-v0", (-200.0, 0.0)))
    rng = np.random.default_rng(0)
    thetas = np.stack([task.actor_spec.initial(rng) for _ in range(2)])
    omegas = np.stack([task.critic_spec.initial(rng) for _ in range(2)])
    trainer = GymnasiumSlotTrainer(task, thetas, omegas, [0, 1], BATCHED, tags=["a", "b"])
    trainer.envs[1].env.unwrapped.fault = "nan-reward"  # the second slot's env, at step 3
    trainer.step(), trainer.step()
    with pytest.raises(SlotEnvironmentError) as error:
        trainer.step()
    assert error.value.tag == "b" and "reward nan at step 3" in str(error.value)


GOLDEN = (
    200,
    "patience",
    0.9302316212837491,
    "e31576f104570f84a6d0fd83eac69d9b82b50ee501dc60b0a4eee80c5132ebcb",
)
GOLDEN_HISTORY = "137a1e4a9ca9fb4030378dfe52a244aeab290717c93dd234e759210bdb89f1b8"


class IntegerObservations(gymnasium.Env):
    """A counter observed as uint8: the scaled float observations must not be cast back."""

    observation_space = gymnasium.spaces.Box(0, 255, (1,), np.uint8)
    action_space = gymnasium.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.array([0], dtype=np.uint8), {}

    def step(self, action):
        self.t += 1
        return np.array([self.t], dtype=np.uint8), -abs(float(action[0])), False, False, {}


gymnasium.register("lonlib-test/IntegerObservations-v0", IntegerObservations, max_episode_steps=20)


def test_an_integer_observation_space_trains():
    task = GymnasiumTask(GymnasiumTaskConfig("lonlib-test/IntegerObservations-v0", (-20.0, 0.0)))
    rng = np.random.default_rng(0)
    hp = dataclasses.replace(BATCHED, warmup_steps=20, max_steps=60)
    result = gymnasium_local_search(
        task, task.actor_spec.initial(rng), task.critic_spec.initial(rng), hp, 0
    )
    assert result.env_steps == 60 and 0 <= result.fitness <= 1


def line_task(name: str = "Line") -> GymnasiumTask:
    return GymnasiumTask(GymnasiumTaskConfig(f"lonlib-test/{name}-v0", (-200.0, 0.0)))


def line_start(task: GymnasiumTask, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return task.actor_spec.initial(rng), task.critic_spec.initial(rng)


def run_alone(task, seed, hp):
    return gymnasium_local_search(task, *line_start(task, seed), hp, seed)


def judged_steps(result) -> list[int]:
    return [r.env_steps for r in result.history if not np.isnan(r.greedy_fitness)]


def test_judge_every_judges_the_episodes_whose_end_crosses_a_multiple_of_it():
    """Line's episodes end every 20 env steps; judged every 50, a trained policy is judged
    at the ends of the episodes that cross 50, 100, 150, ... (and never in the warm-up)."""
    task = line_task()
    hp = dataclasses.replace(
        BATCHED, warmup_steps=20, max_steps=300, min_steps=300, patience_steps=1000, judge_every=50
    )
    result = run_alone(task, 0, hp)
    assert result.env_steps == 300 and len(result.history) == 15
    assert judged_steps(result) == [60, 100, 160, 200, 260, 300]
    assert result.fitness == max(
        r.greedy_fitness for r in result.history if r.env_steps in (60, 100, 160, 200, 260, 300)
    )
    every = run_alone(task, 0, dataclasses.replace(hp, judge_every=0))
    assert judged_steps(every) == list(range(20, 301, 20))  # the first ends with one update


@pytest.mark.parametrize(("patience", "seed", "stop"), [(30, 0, 70), (70, 0, 110), (70, 2, 190)])
def test_patience_counts_from_the_end_of_the_warm_up_and_from_each_improvement(
    patience, seed, stop
):
    """The patience window opens when updates start (at 40, not at step 0: nothing is judged
    before, so a patience of 30 would stop every search at 30) and restarts at every judged
    improvement: the search stops ``patience_steps`` after its last one (seed 2 improves at
    100 and 120)."""
    task = line_task()
    hp = dataclasses.replace(
        BATCHED, warmup_steps=40, max_steps=2000, min_steps=0, patience_steps=patience
    )
    result = run_alone(task, seed, hp)
    best, last = -np.inf, None
    for record in result.history:
        if record.greedy_fitness > best:
            best, last = record.greedy_fitness, record.env_steps
    assert last is not None and last >= hp.warmup_steps
    assert result.stop_reason == "patience" and result.env_steps == last + patience == stop
    assert result.fitness == best and not result.final_evaluation


def test_a_search_that_judged_nothing_returns_its_actor_at_the_stop_scored():
    """No episode ends within the budget (15 env steps of a 20-step episode): the search
    returns the Actor it trained to, scored once at the stop (``final_evaluation``)."""
    task = line_task()
    hp = dataclasses.replace(BATCHED, warmup_steps=5, max_steps=15, min_steps=0)
    theta, omega = line_start(task, 0)
    result = gymnasium_local_search(task, theta, omega, hp, 0)
    assert result.final_evaluation and result.history == []
    assert (result.env_steps, result.updates, result.stop_reason) == (15, 11, "budget")
    assert not np.array_equal(result.theta, theta) and not np.array_equal(result.omega, omega)
    assert result.fitness == task.fitness(result.theta[None])[0] != result.start_fitness


class Sticky(Line):
    """Line whose every push drifts by 0.05 per seeded reset it has had: ``reset`` does not
    clear that count (the greedy episode's seed, 0, leaves it, so the fitness stays a
    function of the Actor), so a search trained in a used environment would differ."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.resets = 0

    def reset(self, *, seed=None, options=None):
        self.resets += bool(seed)
        return super().reset(seed=seed, options=options)

    def step(self, action):
        self.x += 0.05 * self.resets
        return super().step(action)


gymnasium.register("lonlib-test/Sticky-v0", entry_point=Sticky, max_episode_steps=20)


def test_each_search_trains_in_a_fresh_environment():
    """A slot refilled after a search ended trains its new search in a new environment: on
    Sticky, whose reset keeps what the last search did, the refill is bit for bit the search
    alone."""
    task = line_task("Sticky")
    hp = dataclasses.replace(BATCHED, warmup_steps=40, max_steps=600, patience_steps=100)
    alone = run_alone(task, 2, hp)
    with GymnasiumSlotTrainer(task, *(x[None] for x in line_start(task, 0)), [0], hp) as trainer:
        while not trainer.step():
            pass
        theta, omega = line_start(task, 2)
        trainer.start([0], theta[None], omega[None], [2], ["refill"])
        ended = []
        while not ended:
            ended = trainer.step()
    assert ended[0][0] == "refill"
    assert_same_search(ended[0][1], alone)


class Tracked(Line):
    """Line that knows which of its environments are open (``close`` closes one)."""

    OPEN: set[int] = set()

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        Tracked.OPEN.add(id(self))

    def close(self):
        Tracked.OPEN.discard(id(self))


gymnasium.register("lonlib-test/Tracked-v0", entry_point=Tracked, max_episode_steps=20)


def test_a_batch_that_fails_while_it_is_made_closes_its_environments():
    task = line_task("Tracked")
    open_before = set(Tracked.OPEN)
    theta, omega = line_start(task, 0)
    task.env.unwrapped.fault = "raise"  # the start's greedy episode fails, at its step 3
    try:
        with pytest.raises(SlotEnvironmentError, match="contact solver diverged"):
            GymnasiumSlotTrainer(
                task, np.stack([theta] * 2), np.stack([omega] * 2), [0, 1], BATCHED
            )
    finally:
        task.env.unwrapped.fault = ""
    assert open_before == Tracked.OPEN  # the two training environments made are closed
