"""The notebooks run under papermill with tiny parameters, from the repository root (as
``make reproduce``) and from ``notebooks/`` (where JupyterLab starts their kernels), and
read and write one ``data/`` folder."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import papermill as pm
import pytest

from tests.conftest import write_tiny_yaml

REPO = Path(__file__).resolve().parents[2]
NOTEBOOKS = REPO / "notebooks"


def clone_project(root: Path) -> Path:
    """A project laid out as a fresh clone has it (pyproject.toml, notebooks/, an empty
    data/) plus ``quick.yaml``: the tiny test configuration named ``quick``, so that
    sample_lon with ``config="quick.yaml"`` writes data/quick, the other notebooks' default."""
    root.mkdir(parents=True)
    shutil.copy(REPO / "pyproject.toml", root)
    shutil.copytree(NOTEBOOKS, root / "notebooks")
    (root / "data").mkdir()
    tiny = write_tiny_yaml(root)
    (root / "quick.yaml").write_text(tiny.read_text().replace("name: tiny", "name: quick"))
    tiny.unlink()
    return root


def execute(book: Path, out: Path, cwd: Path, **parameters) -> dict:
    """Run ``book`` with papermill's Python API in ``cwd``; the executed notebook as JSON."""
    pm.execute_notebook(
        str(book),
        str(out),
        parameters=parameters,
        progress_bar=False,
        cwd=str(cwd),
        engine_name="lonlib",  # encrypted kernel connection, as make lab and make reproduce
    )
    return json.loads(out.read_text())


def outputs(book: dict) -> list[dict]:
    return [out for cell in book["cells"] for out in cell.get("outputs", [])]


@pytest.mark.parametrize(
    "name", ["sample_lon", "analyse_lon", "record_optima", "calibrate_physics"]
)
def test_notebooks_are_committed_without_outputs_and_with_a_parameters_cell(name):
    import nbformat

    book = nbformat.read(NOTEBOOKS / f"{name}.ipynb", as_version=4)
    assert book.metadata["kernelspec"]["name"] == "python3"
    assert book.metadata["kernelspec"]["language"] == "python"
    assert not any(cell.get("outputs") for cell in book.cells if cell.cell_type == "code")
    assert any("parameters" in cell.metadata.get("tags", []) for cell in book.cells)


def test_notebooks_share_one_data_folder_from_the_root_and_from_notebooks(tmp_path):
    root = clone_project(tmp_path / "clone")
    books, data = root / "notebooks", root / "data" / "quick"
    # As JupyterLab runs it: the kernel in notebooks/.
    execute(books / "sample_lon.ipynb", tmp_path / "s1.ipynb", books, config="quick.yaml", p=1e-3)
    # As `make reproduce` runs it: lonlib.notebook_run from the repository root. The kernel's
    # progress reaches the terminal; no warning about the kernel's connection or tqdm.
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
    }
    command = [sys.executable, "-m", "lonlib.notebook_run", "--log-level", "WARNING"]
    command += ["--no-progress-bar", "notebooks/sample_lon.ipynb", str(tmp_path / "s2.ipynb")]
    command += ["-r", "config", "quick.yaml", "-p", "p", "1e-4", "-p", "workers", "1"]
    run = subprocess.run(command, cwd=root, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert "quick runs: 100%" in run.stderr and "local_searches=" in run.stderr, run.stderr
    assert "best=" in run.stderr
    assert "without encryption" not in run.stderr and "Warning" not in run.stderr, run.stderr
    assert len(list(data.glob("p=*/run_*/trials.parquet"))) == 4
    assert not (books / "data").exists()

    executed = execute(books / "analyse_lon.ipynb", tmp_path / "a.ipynb", books)  # defaults
    pngs = [out for out in outputs(executed) if "image/png" in out.get("data", {})]
    # each figure once: Fig. 2, Figs. 3-5 for both p, robust Figs. 4-5 for both p, retention
    assert len(pngs) == 12
    plots = [
        out for out in outputs(executed) if "application/vnd.plotly.v1+json" in out.get("data", {})
    ]
    assert len(plots) == 2  # the interactive 3-D LON of each p
    tables = [
        "".join(out["data"]["text/markdown"])  # a string or a list of lines
        for out in outputs(executed)
        if "text/markdown" in out.get("data", {})
    ]
    assert len(tables) == 1 and tables[0].startswith("| claim | the paper says |")  # claims
    frames = [
        "".join(out["data"]["text/html"])
        for out in outputs(executed)
        if "text/html" in out.get("data", {})
    ]
    assert any("runs_above_zero" in frame for frame in frames)  # the summary per p
    for name in (
        "fig2_optima_boxplot.png",
        "fig3_lon_p=0.0001.png",
        "fig3_lon_p=0.0001.html",
        "fig4_sinks_p=0.001.png",
        "fig5_optima_p=0.001.png",
        "metrics.csv",
        "peaks.csv",
        "claims.csv",
        "claims.md",
    ):
        assert (data / "figures" / name).stat().st_size > 0, name

    execute(books / "record_optima.ipynb", tmp_path / "r.ipynb", root, show_inline_viewer=False)
    recordings = list((data / "recordings").glob("*.rrd"))
    assert recordings and all(path.stat().st_size > 0 for path in recordings)


def test_a_missing_experiment_says_so_and_what_to_run(tmp_path, capsys):
    from lonlib.analysis.pipeline import load_experiment
    from lonlib.cli import main
    from lonlib.storage.atomic import MissingExperimentError

    folder = tmp_path / "data" / "quick"
    with pytest.raises(MissingExperimentError, match="no experiment in .*`make reproduce`"):
        load_experiment(folder)
    with pytest.raises(SystemExit):
        main(["status", str(folder)])
    error = capsys.readouterr().err
    assert "no such folder" in error and "corrupt" not in error.lower()
    assert not folder.exists()  # nothing created while looking


PENDULUM_V1 = """name: quick
perturbations: [1.0e-3]
runs: 2
tolerance: 1
max_local_searches: 2
task: {gymnasium: Pendulum-v1, fitness_range: [-3254.72, 0.0], episode_steps: 50}
ddpg: {batch_size: 16, buffer_size: 300, warmup_steps: 60, max_steps: 150, min_steps: 0,
       patience_steps: 1000}
"""


def test_the_notebooks_sample_analyse_and_record_a_gymnasium_task(tmp_path):
    root = clone_project(tmp_path / "clone")
    (root / "quick.yaml").write_text(PENDULUM_V1)
    books, data = root / "notebooks", root / "data" / "quick"
    execute(books / "sample_lon.ipynb", tmp_path / "s.ipynb", books, config="quick.yaml", p=1e-3)
    assert len(list(data.glob("p=*/run_*/trials.parquet"))) == 2
    executed = execute(books / "analyse_lon.ipynb", tmp_path / "a.ipynb", books)
    pngs = [out for out in outputs(executed) if "image/png" in out.get("data", {})]
    assert len(pngs) == 4  # Figs. 2-5 of the one p; no conditioning figures
    texts = "".join(
        "".join(out.get("text", "")) + "".join(out.get("data", {}).get("text/markdown", ""))
        for out in outputs(executed)
    )
    assert "skipped (they concern the coupled pendulums)" in texts
    execute(books / "record_optima.ipynb", tmp_path / "r.ipynb", root, show_inline_viewer=False)
    assert list((data / "recordings").glob("best_optimum_p=0.001_*.rrd"))
