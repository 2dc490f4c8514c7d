"""Rerun recordings (``.rrd``) of an optimum's greedy rollout: carts and rods moving.

A recording holds, on the ``step`` timeline (and ``time`` in seconds):

* ``world/track`` (static), ``world/carts`` (boxes), ``world/rods`` and ``world/tether``
  (line strips): the scene, drawn in metres with y up;
* ``sensors/cart_<j>``: the ten normalised Table I sensors of cart j;
* ``actions``: the Actor's outputs; ``upright``: each rod's upright flag;
  ``fitness``: the running Algorithm 1 fitness;

with a blueprint (scene on the left, time series on the right). Everything is simulated
first and sent as whole columns (``send_columns``): per-step logging is ~100x slower.
View with ``rerun FILE.rrd`` (command line) or inline in JupyterLab with ``rerun-notebook``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lonlib.nets import actor_spec, forward_numpy
from lonlib.pendulum import CoupledPendulums, EndReason, PendulumConfig
from lonlib.store import p_label


@dataclass(frozen=True)
class Rollout:
    """A greedy episode, step by step (``T`` = steps executed)."""

    x: np.ndarray  # [T, n] cart centres after each step
    phi: np.ndarray  # [T, n]
    sensors: np.ndarray  # [T, 10n] what the Actor saw before each step
    actions: np.ndarray  # [T, n]
    upright: np.ndarray  # [T, n] bool, after each step
    fitness: np.ndarray  # [T] running fitness
    end_reason: str


def rollout(theta: np.ndarray, config: PendulumConfig, seed: int = 0) -> Rollout:
    """Run the greedy Actor ``theta`` for one episode and keep every step."""
    spec = actor_spec(config.n_carts)
    sim = CoupledPendulums(config, 1, seed)
    xs, phis, seen, acts, ups, fits = [], [], [], [], [], []
    cos_limit = np.cos(config.upright_angle)
    while not sim.done[0]:
        obs = sim.observe()
        action = forward_numpy(spec, theta, obs)
        sim.step(action)
        seen.append(obs[0])
        acts.append(action[0])
        xs.append(sim.x[0].copy())
        phis.append(sim.phi[0].copy())
        ups.append(np.cos(sim.phi[0]) > cos_limit)
        fits.append(sim.fitness[0])
    return Rollout(
        x=np.array(xs),
        phi=np.array(phis),
        sensors=np.array(seen),
        actions=np.array(acts),
        upright=np.array(ups),
        fitness=np.array(fits),
        end_reason=EndReason(int(sim.end_reason[0])).name,
    )


def recording_name(p: float, run: int, fitness: float, label: str = "") -> str:
    """File name carrying p, run and fitness, e.g. ``optimum_p=0.0001_run=3_f=0.220.rrd``."""
    prefix = f"{label}_" if label else ""
    return f"{prefix}optimum_p={p_label(p)}_run={run}_f={fitness:.3f}.rrd"


def record(
    theta: np.ndarray, config: PendulumConfig, path: str | Path, title: str = "lonlib optimum"
) -> Rollout:
    """Simulate the greedy rollout of ``theta`` and save it as a rerun recording."""
    import rerun as rr
    import rerun.blueprint as rrb

    episode = rollout(theta, config)
    steps, n = episode.x.shape
    rec = rr.RecordingStream("lonlib", recording_id=f"{title}-{Path(path).stem}")
    index = [
        rr.TimeColumn("step", sequence=np.arange(1, steps + 1)),
        rr.TimeColumn("time", duration=np.arange(1, steps + 1) * config.dt),
    ]

    half = config.track_half_length
    rec.log(
        "world/track",
        rr.LineStrips2D(
            [[[-half, 0.0], [half, 0.0]], [[-half, 0.0], [-half, 0.3]], [[half, 0.0], [half, 0.3]]],
            colors=[[90, 90, 90]],
            radii=0.01,
        ),
        static=True,
    )
    cart_h = 0.12
    centres = np.stack([episode.x, np.full_like(episode.x, cart_h / 2)], axis=2).reshape(-1, 2)
    rec.send_columns(
        "world/carts",
        index,
        rr.Boxes2D.columns(
            centers=centres,
            half_sizes=np.tile([config.cart_width / 2, cart_h / 2], (steps * n, 1)),
        ).partition([n] * steps),
    )
    rec.log("world/carts", rr.Boxes2D.from_fields(colors=[[40, 90, 170]]), static=True)

    rod = 2 * config.pole_half_length
    base = np.stack([episode.x, np.full_like(episode.x, cart_h)], axis=2)
    tip = base + rod * np.stack([np.sin(episode.phi), np.cos(episode.phi)], axis=2)
    rods = np.stack([base, tip], axis=2).reshape(-1, 2, 2)
    rec.send_columns(
        "world/rods", index, rr.LineStrips2D.columns(strips=rods).partition([n] * steps)
    )
    rec.log(
        "world/rods", rr.LineStrips2D.from_fields(colors=[[200, 60, 40]], radii=[0.02]), static=True
    )
    if n > 1:
        y = np.full_like(episode.x[:, :-1], cart_h / 2)
        left = np.stack([episode.x[:, :-1], y], axis=2)
        right = np.stack([episode.x[:, 1:], y], axis=2)
        tether = np.stack([left, right], axis=2).reshape(-1, 2, 2)
        rec.send_columns(
            "world/tether", index, rr.LineStrips2D.columns(strips=tether).partition([n - 1] * steps)
        )
        rec.log("world/tether", rr.LineStrips2D.from_fields(colors=[[150, 110, 40]]), static=True)

    names = [f"S{i}" for i in range(10)]
    per_cart = episode.sensors.reshape(steps, n, 10)
    for j in range(n):
        entity = f"sensors/cart_{j}"
        rec.log(entity, rr.SeriesLines(names=names), static=True)
        rec.send_columns(
            entity,
            index,
            rr.Scalars.columns(scalars=per_cart[:, j].reshape(-1)).partition([10] * steps),
        )
    series = {
        "actions": (episode.actions, [f"cart {j}" for j in range(n)]),
        "upright": (episode.upright.astype(float), [f"rod {j}" for j in range(n)]),
        "fitness": (episode.fitness[:, None], ["running fitness"]),
    }
    for entity, (values, labels) in series.items():
        rec.log(entity, rr.SeriesLines(names=labels), static=True)
        width = values.shape[1]
        rec.send_columns(
            entity, index, rr.Scalars.columns(scalars=values.reshape(-1)).partition([width] * steps)
        )

    blueprint = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(origin="world", name="carts and rods"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="sensors", name="sensors"),
                rrb.TimeSeriesView(origin="actions", name="actions"),
                rrb.TimeSeriesView(origin="upright", name="upright"),
                rrb.TimeSeriesView(origin="fitness", name="fitness"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec.save(str(path), default_blueprint=blueprint)
    rec.flush(timeout_sec=30)
    rec.disconnect()
    return episode


def recorded_entities(path: str | Path) -> dict[str, int]:
    """Entity paths of a recording and the number of time rows each holds (0: static)."""
    from rerun.chunk import RrdReader

    counts: dict[str, int] = {}
    for chunk in RrdReader(str(path)).stream().to_chunks():
        entity = str(chunk.entity_path)
        rows = 0 if chunk.is_static else int(chunk.num_rows)
        counts[entity] = counts.get(entity, 0) + rows
    return counts


def show_inline(path: str | Path, width: int = 950, height: int = 520) -> None:
    """Show a recording inside JupyterLab (needs ``rerun-notebook``: ``make lab`` installs it).

    Outside a notebook, use the viewer instead: ``rerun FILE.rrd``.
    """
    try:
        import rerun_notebook  # noqa: F401
    except ImportError as error:
        raise ImportError(
            f"inline viewing needs rerun-notebook (pip install 'rerun-notebook==0.41.*'); "
            f"or run: rerun {path}"
        ) from error
    import rerun as rr

    rec = rr.RecordingStream("lonlib", recording_id=f"inline-{Path(path).stem}")
    rec.log_file_from_path(Path(path))
    rec.notebook_show(width=width, height=height)
