"""A Gymnasium task's optional behaviour descriptor (``task.descriptor``,
:mod:`lonlib.task.gymnasium_behaviour`): a user's function of the scored greedy episode,
stored as ``b_*`` columns and a label, replayed, grouped by in the analysis; a wrong name or
return is a one-line error naming the field before any compute."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from lonlib.config import GymnasiumTaskConfig
from lonlib.storage.layout import stored_config
from lonlib.storage.trials import read_optimum
from lonlib.task import GymnasiumTask
from lonlib.task.gymnasium_behaviour import describe_optimum, trace_episode

ROOT = Path(__file__).parents[2]
PENDULUM_V1 = ROOT / "data" / "gymnasium" / "pendulum-v1"


def line_position(trace):
    """The test environment's descriptor: how far the point ends from 0, and a label."""
    end = float(abs(trace.observations[-1, 0]))
    return {"end_distance": end, "steps": len(trace.rewards), "label": "near" if end < 1 else "far"}


def broken(trace):
    return {"spread": float("nan")}


def described_pendulum() -> GymnasiumTask:
    config = stored_config(PENDULUM_V1).task
    descriptor = "lonlib.task.gymnasium_descriptors:pendulum_v1"
    return GymnasiumTask(dataclasses.replace(config, descriptor=descriptor))


def test_the_trace_is_the_scored_episode_and_the_descriptor_replays():
    """On a committed Pendulum-v1 optimum: the traced episode is the one that scores the
    stored fitness, its rewards sum to the return, and describing it twice gives the same
    numbers (what verify relies on)."""
    task = described_pendulum()
    optimum = read_optimum(PENDULUM_V1 / "p=0.001" / "run_0003" / "optimum_0001.npz")
    trace = trace_episode(task, optimum.theta, "test")
    assert trace.episode.fitness == optimum.fitness  # 0.9624...: it swings up and holds
    assert trace.observations.shape == (201, 3) and trace.actions.shape == (200, 1)
    assert np.isclose(trace.rewards.sum(), trace.episode.episode_return, rtol=0, atol=1e-9)
    described = describe_optimum(task, optimum.theta)
    assert described["label"] == "swings up and holds" and described["b_held_end"] == 1.0
    assert described == describe_optimum(task, optimum.theta)
    start = read_optimum(PENDULUM_V1 / "p=0.001" / "run_0003" / "optimum_0000.npz")
    assert describe_optimum(task, start.theta)["label"] != "swings up and holds"  # 0.70


def test_a_task_without_a_descriptor_stores_as_before():
    config = GymnasiumTaskConfig("Pendulum-v1", (-3254.72, 0.0))
    assert "descriptor" not in config.to_dict()  # stored manifests keep their digests
    assert describe_optimum(GymnasiumTask(config), np.zeros(1)) == {}


@pytest.mark.parametrize(
    "descriptor, error",
    [
        ("no_function_named", "task.descriptor must name a function as module:function"),
        ("lonlib.no_such_module:f", "task.descriptor: cannot import 'lonlib.no_such_module'"),
        ("tests.task.test_gymnasium_behaviour:absent", "has no function 'absent'"),
    ],
)
def test_a_descriptor_that_cannot_be_found_is_refused_by_name(descriptor, error):
    with pytest.raises(ValueError) as raised:
        GymnasiumTask(GymnasiumTaskConfig("Pendulum-v1", (-1.0, 0.0), descriptor=descriptor))
    assert error in str(raised.value) and "\n" not in str(raised.value)


@pytest.mark.parametrize(
    "returned, error",
    [
        ([1.0], "must return a mapping"),
        ({"two words": 1.0}, "'two words' is not a name"),
        ({"spread": float("nan")}, "spread must be a finite number"),
        ({"spread": "wide"}, "spread must be a finite number"),
        ({"label": 3}, "label must be non-empty text"),
        ({"label": "two\nlines"}, "label must be non-empty text on one line"),
        ({"label": " "}, "label must be non-empty text on one line"),
    ],
)
def test_a_wrong_return_names_the_descriptor_and_the_entry(returned, error):
    from lonlib.task.gymnasium_behaviour import behaviour_columns

    with pytest.raises(ValueError) as raised:
        behaviour_columns(returned, "my:descriptor")
    assert str(raised.value).startswith("task.descriptor (my:descriptor)") and error in str(
        raised.value
    )


def raising(trace):
    raise KeyError("upright")


CALLS = []


def varying(trace):
    CALLS.append(1)
    return {"x": 1.0} if len(CALLS) == 1 else {"x": 1.0, "label": "late"}


@pytest.mark.parametrize(
    "name, error",
    [
        ("raising", "raised KeyError: 'upright'"),
        ("varying", "must return the same names for every optimum"),
    ],
)
def test_a_descriptor_that_raises_or_varies_is_one_line(name, error):
    config = GymnasiumTaskConfig(
        "Pendulum-v1",
        (-3254.72, 0.0),
        episode_steps=5,
        descriptor=f"tests.task.test_gymnasium_behaviour:{name}",
    )
    task = GymnasiumTask(config)
    theta = task.actor_spec.initial(np.random.default_rng(0))
    with pytest.raises(ValueError) as raised:
        describe_optimum(task, theta)
        describe_optimum(task, theta)
    assert error in str(raised.value) and "\n" not in str(raised.value)


NAMES = ["end_distance"]


def switchable(trace):
    """A descriptor whose names a test changes (as if its code had been edited since)."""
    return {name: float(abs(trace.observations[-1, 0])) for name in NAMES}


def test_the_preflight_describes_a_random_actors_episode_and_leaves_the_names_alone():
    from lonlib.task.gymnasium_behaviour import check_descriptor

    config = GymnasiumTaskConfig(
        "Pendulum-v1",
        (-3254.72, 0.0),
        episode_steps=5,
        descriptor="tests.task.test_gymnasium_behaviour:line_position",
    )
    task = GymnasiumTask(config)
    assert check_descriptor(task) == ["b_end_distance", "b_steps", "label"]
    assert task.descriptor_names is None  # the optima's names are their own to fix
    broken_task = GymnasiumTask(
        dataclasses.replace(config, descriptor="tests.task.test_gymnasium_behaviour:broken")
    )
    with pytest.raises(ValueError, match=r"^task.descriptor \(.*:broken\): spread must be"):
        check_descriptor(broken_task)
    assert check_descriptor(GymnasiumTask(dataclasses.replace(config, descriptor=""))) == []


def test_a_descriptor_module_that_raises_while_imported_is_one_line(tmp_path, monkeypatch):
    (tmp_path / "lonlib_raising_module.py").write_text('raise RuntimeError("boom at\\nimport")\n')
    (tmp_path / "lonlib_exiting_module.py").write_text("import sys\nsys.exit(3)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    config = GymnasiumTaskConfig(
        "Pendulum-v1", (-1.0, 0.0), descriptor="lonlib_raising_module:describe"
    )
    with pytest.raises(ValueError) as raised:
        GymnasiumTask(config)
    text = str(raised.value)
    assert text.startswith("task.descriptor: importing 'lonlib_raising_module' raised")
    assert "RuntimeError: boom at import" in text and "\n" not in text
    with pytest.raises(ValueError, match="importing 'lonlib_exiting_module' raised SystemExit: 3"):
        GymnasiumTask(dataclasses.replace(config, descriptor="lonlib_exiting_module:describe"))
