"""Rerun recordings (``.rrd``) of a Gymnasium task's optimum: its greedy episode, the one
the stored fitness scores (:meth:`lonlib.task.gymnasium_task.GymnasiumTask.greedy_episode`).

A recording holds, on the ``step`` timeline: ``observations`` (what the Actor read: scaled),
``actions`` (the environment's actions), ``reward`` and the running ``return``; and, when the
environment renders ``rgb_array`` frames, ``frames`` (JPEG images, at most
:data:`MAX_FRAMES` of them, evenly spaced, so that a long episode stays a few megabytes).
Its ``optimum`` property holds the episode's fitness, return and length and the trial it
shows (p, run, index, stored fitness), as the pendulums' recordings do, so
``lonlib verify`` checks both alike.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from lonlib.analysis.recordings import APP_ID, recording_id
from lonlib.task.gymnasium_task import Episode, GymnasiumTask, make_environment

MAX_FRAMES = 200
JPEG_QUALITY = 80


def render_environment(task: GymnasiumTask) -> tuple[Any, str]:
    """An environment of the task that renders ``rgb_array`` frames, or the task's own and
    the one-line reason why it has none (no such render mode, or a missing dependency)."""
    modes = (task.env.metadata or {}).get("render_modes", [])
    if "rgb_array" not in modes:
        return task.env, f"{task.name} renders no rgb_array frames (its modes: {modes})"
    try:
        env = make_environment(task.config, render_mode="rgb_array")
        env.reset(seed=task.config.eval_seed)
        env.render()
    except Exception as error:  # e.g. gymnasium.error.DependencyNotInstalled (pygame)
        return task.env, f"{task.name} cannot render here: {' '.join(str(error).split())}"
    return env, ""


def record_task(
    task: GymnasiumTask,
    theta: np.ndarray,
    path: str | Path,
    title: str = "lonlib optimum",
    properties: dict[str, float | int | str] | None = None,
) -> tuple[Episode, str]:
    """Run the greedy Actor ``theta`` (the episode its fitness scores) and save it as a rerun
    recording; return the episode and why it has no frames ("" when it has them)."""
    import rerun as rr

    env, no_frames = render_environment(task)
    observations, actions, rewards, frames = [], [], [], []
    stride = max(1, -(-task.episode_steps // MAX_FRAMES))  # ceil: at most MAX_FRAMES

    def on_step(step: int, obs: np.ndarray, unit_action: np.ndarray, reward: float) -> None:
        observations.append(obs)
        actions.append(task.env_action(unit_action).astype(np.float64))
        rewards.append(reward)
        if not no_frames and (step - 1) % stride == 0:
            frames.append((step, env.render()))

    episode = task.greedy_episode(theta, f"recording {Path(path).name}", env, on_step)
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id(path))
    rec.send_recording_name(title)
    rec.send_property(
        "optimum",
        rr.AnyValues(
            fitness=float(episode.fitness),
            episode_return=float(episode.episode_return),
            end_step=int(episode.length),
            task=task.name,
            **(properties or {}),
        ),
    )
    steps = len(rewards)
    index = [rr.TimeColumn("step", sequence=np.arange(1, steps + 1))]
    series = {
        "observations": np.array(observations).reshape(steps, -1),
        "actions": np.array(actions).reshape(steps, -1),
        "reward": np.array(rewards)[:, None],
        "return": np.cumsum(rewards)[:, None],
    }
    for entity, values in series.items():
        width = values.shape[1]
        rec.log(entity, rr.SeriesLines(names=[f"{entity} {j}" for j in range(width)]), static=True)
        rec.send_columns(
            entity, index, rr.Scalars.columns(scalars=values.reshape(-1)).partition([width] * steps)
        )
    for step, frame in frames:
        rec.set_time("step", sequence=step)
        rec.log("frames", rr.Image(np.asarray(frame)).compress(jpeg_quality=JPEG_QUALITY))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec.save(str(path))
    rec.flush(timeout_sec=30)
    rec.disconnect()
    if env is not task.env:
        env.close()
    return episode, no_frames


__all__ = ["MAX_FRAMES", "record_task", "render_environment"]
