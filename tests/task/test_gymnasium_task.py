"""A Gymnasium environment as the task: shapes and maps from its spaces, the one fitness
function, and a clear one-line error for an environment that fails or misbehaves."""

import gymnasium
import numpy as np
import pytest
from gymnasium import spaces

from lonlib.config.task import GymnasiumTaskConfig
from lonlib.task import GymnasiumTask, TaskEnvironmentError
from lonlib.task.policy import forward_numpy


class Line(gymnasium.Env):
    """A point on a line pushed by its action; reward -|x|; ``fault`` makes it misbehave at
    step ``at``: raise, return NaN, or change its observation space."""

    FAULT = ""  # the fault of environments made without one (a test may set it)
    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self, fault: str = "", at: int = 3, discrete: bool = False, render_mode: str | None = None
    ):
        self.fault, self.at, self.render_mode = fault or Line.FAULT, at, render_mode
        self.observation_space = spaces.Box(-10.0, 10.0, (2,), np.float64)
        self.action_space = (
            spaces.Discrete(3) if discrete else spaces.Box(-1.0, 1.0, (1,), np.float32)
        )
        self.x, self.t = 0.0, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if self.fault == "reset":
            raise RuntimeError("the simulator could not start")
        self.x, self.t = float(self.np_random.uniform(-1, 1)), 0
        return np.array([self.x, 0.0]), {}

    def step(self, action):
        self.t += 1
        self.x += float(action[0])
        obs, reward = np.array([self.x, self.t / 10.0]), -abs(self.x)
        if self.t == self.at and self.fault == "raise":
            raise ValueError("contact solver diverged")
        if self.t == self.at and self.fault == "nan-observation":
            obs[0] = np.nan
        if self.t == self.at and self.fault == "nan-reward":
            reward = float("nan")
        if self.t == self.at and self.fault == "spaces":
            self.observation_space = spaces.Box(-10.0, 10.0, (3,), np.float64)
        return obs, reward, False, False, {}

    def render(self):
        """A 16 x 32 frame with the point drawn at its position."""
        frame = np.zeros((16, 32, 3), dtype=np.uint8)
        frame[:, int(np.clip(16 + self.x, 0, 31))] = 255
        return frame


gymnasium.register("lonlib-test/Line-v0", entry_point=Line, max_episode_steps=20)


def task(**kwargs) -> GymnasiumTask:
    config = GymnasiumTaskConfig("lonlib-test/Line-v0", (-200.0, 0.0), kwargs=kwargs)
    return GymnasiumTask(config)


def test_shapes_and_maps_follow_the_spaces():
    line = task()
    assert line.actor_spec.sizes == (2, 20, 20, 20, 1) and line.actor_spec.sigmoid_output
    assert line.critic_spec.sizes == (3, 20, 20, 20, 1)
    assert line.episode_steps == 20  # the registered TimeLimit
    np.testing.assert_array_equal(line.env_action(np.array([0.0, 0.5, 1.0]))[[0]], [-1.0])
    assert line.env_action(np.array([0.5]))[0] == 0.0 and line.env_action([1.7])[0] == 1.0
    np.testing.assert_array_equal(line.observe(np.array([5.0, -10.0])), [0.5, -1.0])


def test_the_fitness_is_the_greedy_episode_return_normalised():
    line = task()
    theta = line.actor_spec.initial(np.random.default_rng(0))
    episode = line.greedy_episode(theta)
    # the same episode by hand: reset(seed=0), forward_numpy, the bounds map
    env = gymnasium.make("lonlib-test/Line-v0")
    obs, _ = env.reset(seed=0)
    total = 0.0
    for _ in range(20):
        unit = forward_numpy(line.actor_spec, theta, line.observe(obs)[None])[0]
        obs, reward, *_ = env.step(line.env_action(unit))
        total += reward
    assert episode.episode_return == total and episode.length == 20
    assert episode.fitness == (total + 200.0) / 200.0
    assert line.fitness(np.stack([theta, theta])).tolist() == [episode.fitness] * 2


@pytest.mark.parametrize(
    ("fault", "message"),
    [
        ("reset", "raised in reset: RuntimeError: the simulator could not start"),
        ("raise", "raised at step 3: ValueError: contact solver diverged"),
        ("nan-observation", "returned a non-finite observation at step 3:"),
        ("nan-reward", "returned the reward nan at step 3"),
        ("spaces", "changed its observation or action space at step 3;"),
    ],
)
def test_a_misbehaving_environment_is_one_line_naming_the_call_and_step(fault, message):
    line = task(fault=fault)
    theta = line.actor_spec.initial(np.random.default_rng(0))
    with pytest.raises(TaskEnvironmentError) as error:
        line.greedy_episode(theta, where="run (p=0.001, run=0)")
    text = str(error.value)
    assert "\n" not in text and text.startswith("run (p=0.001, run=0): lonlib-test/Line-v0")
    assert message in text and "(step" not in text  # said once: "at step 3", not "(step 3)"


@pytest.mark.parametrize(
    ("config", "message"),
    [
        (GymnasiumTaskConfig("NoSuchEnv-v0", (0.0, 1.0)), "task.gymnasium 'NoSuchEnv-v0'"),
        (GymnasiumTaskConfig("CartPole-v1", (0.0, 500.0)), "Discrete action space"),
        (
            GymnasiumTaskConfig("lonlib-test/Line-v0", (0.0, 1.0), kwargs={"discrete": True}),
            "the Actor needs a continuous (Box) one",
        ),
        (
            GymnasiumTaskConfig("lonlib-test/Line-v0", (0.0, 1.0), kwargs={"colour": "red"}),
            "could not be made: TypeError",
        ),
        (GymnasiumTaskConfig("no_such_module:Env-v0", (0.0, 1.0)), "task.gymnasium"),
    ],
)
def test_a_bad_environment_is_refused_when_the_task_is_made(config, message):
    with pytest.raises(ValueError) as error:
        GymnasiumTask(config)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_bounds_scaling_leaves_infinite_entries_and_none_leaves_all():
    space = spaces.Box(np.array([-2.0, -np.inf]), np.array([2.0, np.inf]), dtype=np.float64)
    from lonlib.task.gymnasium_task import observation_scaling

    centre, scale = observation_scaling(space, GymnasiumTaskConfig("X", (0.0, 1.0)))
    assert centre.tolist() == [0.0, 0.0] and scale.tolist() == [2.0, 1.0]
    config = GymnasiumTaskConfig("X", (0.0, 1.0), observation_scaling="none")
    assert observation_scaling(space, config)[1].tolist() == [1.0, 1.0]
