"""The ``task:`` section of an experiment's YAML: what is checked without the environment,
and the pendulums' stored form left as it was."""

import pytest

from lonlib.config import ExperimentConfig
from lonlib.config.task import GymnasiumTaskConfig

PENDULUM = {"gymnasium": "Pendulum-v1", "fitness_range": [-3254.72, 0.0]}


def test_a_task_round_trips_through_its_stored_form():
    config = ExperimentConfig.from_mapping(
        {"name": "g", "task": {**PENDULUM, "kwargs": {"g": 9.81}}}
    )
    assert config.task == GymnasiumTaskConfig("Pendulum-v1", (-3254.72, 0.0), kwargs={"g": 9.81})
    assert ExperimentConfig.from_mapping(config.to_dict()) == config
    assert config.comparable()["task"]["kwargs"] == {"g": 9.81}  # a changed task changes results


def test_the_pendulums_stored_form_has_no_task_key():
    """Committed experiments' manifests (and their config digests) stay as they were."""
    assert "task" not in ExperimentConfig().to_dict()
    assert "task" not in ExperimentConfig().comparable()


@pytest.mark.parametrize(
    ("task", "names"),
    [
        ({"fitness_range": [0, 1]}, "task.gymnasium is required"),
        ({"gymnasium": "Pendulum-v1"}, "task.fitness_range is required"),
        ({**PENDULUM, "fitness_range": [0, 0]}, "task.fitness_range must be two finite"),
        ({**PENDULUM, "fitness_range": [0, float("nan")]}, "task.fitness_range must be two"),
        ({**PENDULUM, "fitness_range": [0]}, "task.fitness_range must be two"),
        ({**PENDULUM, "episode_steps": -1}, "task.episode_steps"),
        ({**PENDULUM, "search": "ppo"}, "task.search must be one of"),
        ({**PENDULUM, "observation_scaling": "z"}, "task.observation_scaling must be one of"),
        ({**PENDULUM, "kwargs": {"f": object()}}, "task.kwargs must hold JSON values"),
        ({**PENDULUM, "seed": 1}, "unknown task key(s) ['seed']"),
        ("Pendulum-v1", "task must be a mapping"),
    ],
)
def test_a_bad_task_section_is_one_line_naming_the_field(task, names):
    with pytest.raises(ValueError, match=None) as error:
        ExperimentConfig.from_mapping({"task": task})
    assert names in str(error.value) and "\n" not in str(error.value)


def test_a_task_refuses_pendulum_physics_and_lockstep_for_a_foreign_learner():
    with pytest.raises(ValueError, match="env: the coupled pendulums' physics"):
        ExperimentConfig.from_mapping({"task": PENDULUM, "env": {"n_carts": 1}})
    ExperimentConfig.from_mapping({"task": PENDULUM, "executor": "lockstep"})  # lonlib's DDPG
    with pytest.raises(ValueError, match="executor: lockstep batches lonlib's DDPG"):
        ExperimentConfig.from_mapping(
            {"task": {**PENDULUM, "search": "sb3-td3"}, "executor": "lockstep"}
        )


def test_the_fitness_maps_the_range_onto_zero_one_and_clips():
    task = GymnasiumTaskConfig("X", (-100.0, 100.0))
    assert [task.normalise(r) for r in (-100.0, 0.0, 50.0, 100.0)] == [0.0, 0.5, 0.75, 1.0]
    assert task.normalise(-1e9) == 0.0 and task.normalise(1e9) == 1.0
