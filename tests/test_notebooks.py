"""Each notebook runs under papermill with tiny parameters and writes its outputs."""

from pathlib import Path

import papermill as pm
import pytest

NOTEBOOKS = Path(__file__).parent.parent / "notebooks"


def execute(name, tmp_path, **parameters):
    out = tmp_path / f"{name}.out.ipynb"
    pm.execute_notebook(
        str(NOTEBOOKS / f"{name}.ipynb"),
        str(out),
        parameters=parameters,
        progress_bar=False,
        cwd=str(tmp_path),
    )
    assert out.stat().st_size > 0
    return out


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


def test_sample_analyse_and_record_notebooks(tmp_path):
    from tests.conftest import write_tiny_yaml

    yaml_path = write_tiny_yaml(tmp_path)
    folder = tmp_path / "experiment"
    for p in (1e-3, 1e-4):
        execute("sample_lon", tmp_path, config=str(yaml_path), p=p, workers=1, out=str(folder))
    assert len(list(folder.glob("p=*/run_*/trials.parquet"))) == 4
    execute("analyse_lon", tmp_path, experiment_dir=str(folder))
    figures = folder / "figures"
    for name in (
        "fig2_optima_boxplot.png",
        "fig3_lon_p=0.0001.png",
        "fig3_lon_p=0.0001.html",
        "fig4_sinks_p=0.001.png",
        "fig5_optima_p=0.001.png",
        "metrics.csv",
        "peaks.csv",
    ):
        assert (figures / name).stat().st_size > 0, name
    execute("record_optima", tmp_path, experiment_dir=str(folder), show_inline_viewer=False)
    recordings = list((folder / "recordings").glob("*.rrd"))
    assert recordings and all(path.stat().st_size > 0 for path in recordings)
