"""Rerun recordings (``.rrd``) of an optimum's greedy rollout: carts and rods moving.

A recording holds, on the ``step`` timeline (and ``time`` in seconds):

* ``world/track`` (static), ``world/carts`` (boxes), ``world/rods`` and ``world/tether``
  (line strips): the scene, in metres, x along the track and y = minus the height above it
  (rerun's 2-D views draw y pointing down, so this draws an upright rod up and a hanging
  rod hanging), framed on the whole track;
* ``sensors/cart_<j>``: the ten normalised Table I sensors of cart j;
* ``actions``: the Actor's outputs; ``upright``: each rod's upright flag;
  ``fitness``: the running Algorithm 1 fitness;

with a blueprint (scene on the left, time series on the right) saved in the file.
Everything is simulated first and sent as whole columns (``send_columns``): per-step
logging is ~100x slower. View with ``rerun FILE.rrd`` (command line) or inline in
JupyterLab with :func:`show_inline` (``rerun-notebook``).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lonlib.config import PendulumConfig, Scoring
from lonlib.task.rollout import Rollout, run_actors
from lonlib.util.labels import p_label


def recording_name(
    p: float, run: int, fitness: float, role: str = "", behaviour: str = "", label: str = ""
) -> str:
    """A recording's file name; the one naming scheme of recordings.

    ``[<role>_][<behaviour>_]optimum_p=<p>_run=<run>_f=<fitness>.rrd``: parts joined by
    ``_``, words inside a part by ``-``. ``role`` says why the optimum was chosen
    (:func:`lonlib.analysis.pipeline.optima_to_record`: ``best``, ``label-best``,
    ``sink-peak-0.33``), ``behaviour`` is its behaviour label's slug (``spinning-in-phase``),
    e.g. ``label-best_crash_optimum_p=0.0001_run=3_f=0.372.rrd``; without either,
    ``optimum_p=0.0001_run=3_f=0.220.rrd``. ``label`` is the older name of ``role``.
    """
    parts = [part for part in (role or label, behaviour) if part]
    prefix = "".join(f"{part}_" for part in parts)
    return f"{prefix}optimum_p={p_label(p)}_run={run}_f={fitness:.3f}.rrd"


APP_ID = "lonlib"  # a valid rerun entry name: letters and '_' only (no '=', '.', spaces)
CART_HEIGHT = 0.12  # metres, drawing only


def recording_id(path: str | Path) -> str:
    """A rerun recording id made from a file name: letters, digits, '-' and '_' only."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", Path(path).stem)


def scene_height(height: np.ndarray) -> np.ndarray:
    """A height above the track as a y coordinate of the scene: rerun's 2-D views draw y
    pointing down (image convention), so heights are negated to draw upright things up."""
    return -np.asarray(height, dtype=float)


@dataclass(frozen=True)
class Scene:
    """What the 2-D view draws, in scene coordinates (:func:`scene_height`), step by step."""

    track: np.ndarray  # [3, 2, 2] the track and its two end posts (static)
    cart_centres: np.ndarray  # [T, n, 2] carts sit on the track; rods hinge at their centres
    rods: np.ndarray  # [T, n, 2, 2] hinge -> tip (phi = 0 up, pi hanging)
    tether: np.ndarray  # [T, n - 1, 2, 2] centre to centre of neighbouring carts


def scene(x: np.ndarray, phi: np.ndarray, config: PendulumConfig) -> Scene:
    """The scene for cart centres ``x`` [T, n] and rod angles ``phi`` [T, n]."""
    half = config.track_half_length
    post = float(scene_height(0.3))
    track = np.array(
        [[[-half, 0.0], [half, 0.0]], [[-half, 0.0], [-half, post]], [[half, 0.0], [half, post]]]
    )
    centres = np.stack([x, np.full_like(x, scene_height(CART_HEIGHT / 2))], axis=-1)
    tip = np.stack([np.sin(phi), scene_height(np.cos(phi))], axis=-1)
    rods = np.stack([centres, centres + 2 * config.pole_half_length * tip], axis=-2)
    tether = np.stack([centres[:, :-1], centres[:, 1:]], axis=-2)
    return Scene(track, centres, rods, tether)


def scene_bounds(config: PendulumConfig, margin: float = 0.15) -> tuple[tuple[float, float], ...]:
    """The (x, y) ranges that frame the whole track and the rods in every position."""
    half = config.track_half_length + margin
    reach = 2 * config.pole_half_length + CART_HEIGHT / 2 + margin
    return (-half, half), (-reach, reach)


def recording_blueprint(config: PendulumConfig):
    """The recording's layout: the scene framed on the whole track (left), time series of
    sensors, actions, upright flags and fitness (right)."""
    import rerun.blueprint as rrb

    x_range, y_range = scene_bounds(config)
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(
                origin="world",
                name="carts and rods",
                visual_bounds=rrb.VisualBounds2D(x_range=x_range, y_range=y_range),
            ),
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


def record(
    theta: np.ndarray,
    config: PendulumConfig,
    path: str | Path,
    title: str = "lonlib optimum",
    scoring: Scoring = Scoring(),
    properties: dict[str, float | int | str] | None = None,
) -> Rollout:
    """Run the greedy Actor ``theta`` from the nominal start by the one rollout (the episode
    its fitness scores) and save it as a rerun recording named ``title`` in the viewer.

    The recording's ``optimum`` property holds the episode's fitness under both
    aggregations, its end reason and step, and ``properties`` (e.g. p, run, index and the
    stored fitness). Returns the rollout (with its trace)."""
    import rerun as rr

    result = run_actors(theta, config, eval_seed=scoring.eval_seed, trace=True)
    episode = result.trace.row(0, int(result.end_step[0]))
    steps, n = episode.x.shape
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id(path))
    rec.send_recording_name(title)
    rec.send_property(
        "optimum",
        rr.AnyValues(
            fitness=float(result.fitness[0]),
            fitness_all=float(result.fitness_all[0]),
            fitness_mean=float(result.fitness_mean[0]),
            end_reason=result.end_reason_name(0),
            end_step=int(result.end_step[0]),
            **(properties or {}),
        ),
    )
    index = [
        rr.TimeColumn("step", sequence=np.arange(1, steps + 1)),
        rr.TimeColumn("time", duration=np.arange(1, steps + 1) * config.dt),
    ]

    drawn = scene(episode.x, episode.phi, config)
    rec.log(
        "world/track", rr.LineStrips2D(drawn.track, colors=[[90, 90, 90]], radii=0.01), static=True
    )
    rec.send_columns(
        "world/carts",
        index,
        rr.Boxes2D.columns(
            centers=drawn.cart_centres.reshape(-1, 2),
            half_sizes=np.tile([config.cart_width / 2, CART_HEIGHT / 2], (steps * n, 1)),
        ).partition([n] * steps),
    )
    rec.log("world/carts", rr.Boxes2D.from_fields(colors=[[40, 90, 170]]), static=True)
    rec.send_columns(
        "world/rods",
        index,
        rr.LineStrips2D.columns(strips=drawn.rods.reshape(-1, 2, 2)).partition([n] * steps),
    )
    rec.log(
        "world/rods", rr.LineStrips2D.from_fields(colors=[[200, 60, 40]], radii=[0.02]), static=True
    )
    if n > 1:
        tether = drawn.tether.reshape(-1, 2, 2)
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

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec.save(str(path), default_blueprint=recording_blueprint(config))
    rec.flush(timeout_sec=30)
    rec.disconnect()
    return result


def recorded_entities(path: str | Path) -> dict[str, int]:
    """Entity paths of a recording and the number of time rows each holds (0: static)."""
    from rerun.chunk import RrdReader

    counts: dict[str, int] = {}
    for chunk in RrdReader(str(path)).stream().to_chunks():
        entity = str(chunk.entity_path)
        rows = 0 if chunk.is_static else int(chunk.num_rows)
        counts[entity] = counts.get(entity, 0) + rows
    return counts


def show_inline(path: str | Path, width: int | str = "auto", height: int = 560) -> None:
    """Show a recording inside JupyterLab, with its own layout, offline.

    ``width``: pixels, or ``"auto"`` (the cell's width). Needs ``rerun-notebook`` (``make
    lab`` installs it). Its viewer (JavaScript and WebAssembly) is served from this kernel's
    machine (``RERUN_NOTEBOOK_ASSET=serve-local``) unless the variable is set otherwise
    before the first call; rerun-notebook's own default fetches it from app.rerun.io. For a
    JupyterLab whose browser runs on another machine, set ``RERUN_NOTEBOOK_ASSET=inline``
    (the viewer travels inside the notebook, ~23 MB). The file's bytes are sent as they
    are, so the viewer applies the blueprint saved in it; it plays from the start in real
    time. Outside a notebook, use ``rerun FILE.rrd``.
    """
    os.environ.setdefault("RERUN_NOTEBOOK_ASSET", "serve-local")
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # the asset server's start-up chatter
            import rerun_notebook
    except ImportError as error:
        raise ImportError(
            f"inline viewing needs rerun-notebook (pip install 'rerun-notebook==0.41.*'); "
            f"or run: rerun {path}"
        ) from error
    from IPython.display import display

    if rerun_notebook.ASSET_ENV.startswith("https://app.rerun.io"):
        warnings.warn(
            "rerun_notebook was imported before lonlib.analysis.recordings.show_inline and "
            "fetches its viewer "
            "from app.rerun.io (needs the internet); restart the kernel, or set "
            "RERUN_NOTEBOOK_ASSET=serve-local before importing it",
            stacklevel=2,
        )
    viewer = rerun_notebook.Viewer(width=width, height=height)
    display(viewer)
    viewer.send_rrd(Path(path).read_bytes())
    viewer.set_time_ctrl("time", duration_nanos=0, play=True)  # play from the start, in real time


def recording_properties(path: str | Path) -> dict[str, float | int | str]:
    """The ``optimum`` property of a recording made by :func:`record` (fitness under both
    aggregations, end reason and step, and e.g. p, run, index): empty if it has none."""
    from rerun.chunk import RrdReader

    for chunk in RrdReader(str(path)).stream().to_chunks():
        if str(chunk.entity_path) != "/__properties/optimum":
            continue
        batch = chunk.to_record_batch()
        return {
            name: batch.column(name)[0][0].as_py()
            for name in batch.schema.names
            if not name.startswith("rerun.")
        }
    return {}


def recordings_index(
    folder: str | Path, files: Iterable[Path] | None = None
) -> dict[str, dict[str, float | int | None]]:
    """Every recording of an experiment folder (``recordings/*.rrd``) with the trial it shows
    (``p``, ``run``, ``index``) and that trial's stored fitness, read from its ``optimum``
    property: the index the folder's seal keeps (:mod:`lonlib.storage.digests`). ``files``:
    those recordings instead (written under a temporary name before they are put in place,
    :mod:`lonlib.storage.outputs`), by file name."""
    index = {}
    chosen = (Path(folder) / "recordings").glob("*.rrd") if files is None else files
    for path in sorted(Path(p) for p in chosen):
        props = recording_properties(path)
        index[path.name] = {
            "p": props.get("p"),
            "run": props.get("run"),
            "index": props.get("index"),
            "fitness": props.get("stored_fitness", props.get("fitness")),
        }
    return index
