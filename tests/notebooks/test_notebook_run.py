"""lonlib.notebook_run (papermill's engine ``lonlib``): the kernel's connection is encrypted
whatever ``python3`` kernelspec file Jupyter finds first, and the terminal gets no warning."""

import json
import subprocess
import sys

import nbformat
import papermill as pm
import pytest

from lonlib.notebook_run import declares_curve, runs_this_ipykernel

# A kernel cell that reports whether its sockets use the CurveZMQ keys jupyter_client gave it.
REPORT = """\
from ipykernel.kernelapp import IPKernelApp
print("encrypted" if IPKernelApp.instance().curve_secretkey is not None else "plain", x)
"""


def tiny_notebook(path):
    book = nbformat.v4.new_notebook()
    book.metadata["kernelspec"] = {"name": "python3", "language": "python", "display_name": "P"}
    book.cells = [
        nbformat.v4.new_code_cell("x = 1", metadata={"tags": ["parameters"]}),
        nbformat.v4.new_code_cell(REPORT),
    ]
    nbformat.write(book, path)
    return path


def printed(path) -> str:
    book = json.loads(path.read_text())
    return "".join("".join(out.get("text", "")) for out in book["cells"][-1]["outputs"])


@pytest.fixture
def old_kernelspec_first(tmp_path, monkeypatch):
    """A ``python3`` kernelspec as ipykernel < 7.3 wrote it (no ``supported_encryption``),
    found before the environment's own (``JUPYTER_PATH`` comes first)."""
    folder = tmp_path / "jupyter" / "kernels" / "python3"
    folder.mkdir(parents=True)
    spec = {
        "argv": ["python", "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "Python 3 (ipykernel)",
        "language": "python",
        "metadata": {"debugger": True},
    }
    (folder / "kernel.json").write_text(json.dumps(spec))
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path / "jupyter"))


@pytest.mark.parametrize("kernelspec", ["the environment's", "an older one first"])
def test_the_kernel_connection_is_encrypted_and_the_kernel_does_not_warn(
    kernelspec, tmp_path, capfd, request
):
    if kernelspec == "an older one first":
        request.getfixturevalue("old_kernelspec_first")
    book, out = tiny_notebook(tmp_path / "in.ipynb"), tmp_path / "out.ipynb"
    pm.execute_notebook(book, out, parameters={"x": 2}, engine_name="lonlib", progress_bar=False)
    assert printed(out) == "encrypted 2\n"
    assert "without encryption" not in capfd.readouterr().err


def test_papermills_own_engine_leaves_the_connection_plain_with_an_older_kernelspec(
    old_kernelspec_first, tmp_path, capfd
):
    """What the engine above fixes: papermill's default engine, even told to encrypt when
    the kernelspec allows it, gets a plain connection and ipykernel's warning."""
    from traitlets.config import Config

    config = Config()
    config.KernelManager.transport_encryption = "auto"
    book, out = tiny_notebook(tmp_path / "in.ipynb"), tmp_path / "out.ipynb"
    pm.execute_notebook(book, out, progress_bar=False, config=config)
    assert printed(out) == "plain 1\n"
    assert "without encryption" in capfd.readouterr().err


def test_curve_support_is_read_from_either_form_ipykernel_writes():
    assert declares_curve({"supported_encryption": "curve"})  # ipykernel 7.3
    assert declares_curve({"supported_encryption": ["curve"]})  # ipykernel 7.4
    assert not declares_curve({"debugger": True})
    assert not declares_curve(None)


def test_only_this_interpreters_ipykernel_counts_as_this_ipykernel():
    assert runs_this_ipykernel(["python", "-m", "ipykernel_launcher", "-f", "{connection_file}"])
    assert runs_this_ipykernel([sys.executable, "-m", "ipykernel", "-f", "{connection_file}"])
    assert not runs_this_ipykernel(["/opt/other/python", "-m", "ipykernel_launcher"])
    assert not runs_this_ipykernel(["python", "-m", "other_kernel"])
    assert not runs_this_ipykernel([])


@pytest.mark.parametrize(
    "first, second",
    [("lonlib.notebook_run", "papermill.engines"), ("papermill.engines", "lonlib.notebook_run")],
)
def test_the_engine_imports_in_either_order_and_papermill_registers_the_same_class(first, second):
    code = (
        f"import {first}, {second}; import lonlib.notebook_run as run, papermill.engines as pe; "
        "engine = run.TerminalEngine; "
        "assert pe.papermill_engines.get_engine('lonlib') is engine, 'two classes'; "
        "assert issubclass(engine, pe.NBClientEngine); print(engine.__qualname__)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "TerminalEngine"
