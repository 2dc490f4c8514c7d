"""The package layout's rule, guarded here rather than only by lint: lonlib's subpackages import
one way (import-linter's contracts in pyproject.toml, imports inside functions included), the
analysis side never loads torch, no module is part of an import cycle, no private name is
imported from another module, and no module is longer than a reader can hold (700 lines)."""

import ast
import importlib
import subprocess
import sys
from pathlib import Path

import grimp
import pytest

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / "lonlib"
SUBPACKAGES = sorted(p.parent.name for p in PACKAGE.glob("*/__init__.py"))


def test_the_import_linter_contracts_hold():
    """The ``layers`` and ``forbidden`` contracts of ``[tool.importlinter]``."""
    lint = Path(sys.executable).parent / "lint-imports"
    done = subprocess.run(
        [str(lint), "--no-cache", "--config", str(REPO / "pyproject.toml")],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "0 broken" in done.stdout


def test_no_module_is_part_of_an_import_cycle():
    graph = grimp.build_graph("lonlib", cache_dir=None)
    modules = sorted(m for m in graph.modules if m.startswith("lonlib"))
    imports = {
        m: sorted(d for d in graph.find_modules_directly_imported_by(m) if d.startswith("lonlib"))
        for m in modules
    }
    cycles = []
    for module in modules:
        for imported in imports[module]:
            if imported != module and graph.chain_exists(imported, module):
                cycles.append(graph.find_shortest_chain(imported, module))
    assert not cycles, f"import cycles: {cycles}"


def test_importing_the_analysis_leaves_torch_unloaded():
    code = (
        "import sys, lonlib.analysis, lonlib.lon, lonlib.storage, lonlib.task; "
        "print('torch' in sys.modules)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "False"


def private_imports() -> list[str]:
    """``from lonlib.x import _name`` anywhere in the package: a private name crossing modules."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("lonlib"):
                for alias in node.names:
                    if alias.name.startswith("_"):
                        found.append(f"{path.relative_to(REPO)}: {node.module}.{alias.name}")
    return found


def test_no_private_name_is_imported_across_modules():
    assert private_imports() == []


MOST_LINES = 700
"""The longest a module of lonlib may be: a longer one is split by job into modules of its
subpackage (private ``_name.py`` ones where its public names stay importable from it)."""


def test_no_module_is_over_700_lines():
    lines = {
        path.relative_to(REPO).as_posix(): len(path.read_text().splitlines())
        for path in sorted(PACKAGE.rglob("*.py"))
    }
    assert lines, "no module found"
    assert {path: n for path, n in lines.items() if n > MOST_LINES} == {}


@pytest.mark.parametrize("name", SUBPACKAGES)
def test_every_subpackage_re_exports_its_public_names(name):
    package = importlib.import_module(f"lonlib.{name}")
    assert package.__doc__, f"lonlib.{name} says what it is for"
    assert package.__all__ == sorted(set(package.__all__))
    for exported in package.__all__:
        assert hasattr(package, exported), f"lonlib.{name}.{exported}"


CONFIGURATIONS = {
    "lonlib/config/pendulum.py": "PendulumConfig",
    "lonlib/config/scoring.py": "Scoring",
    "lonlib/config/search.py": "BasinHoppingConfig",
    "lonlib/config/experiment.py": "ExperimentConfig",
    "lonlib/config/calibration.py": "CalibrationConfig",
}


@pytest.mark.parametrize(
    "path, name",
    [
        *CONFIGURATIONS.items(),
        ("lonlib/config/ddpg.py", "DDPGConfig"),
        ("lonlib/config/calibration.py", "Cell"),
        ("lonlib/config/calibration.py", "StartSpread"),
    ],
)
def test_every_field_of_a_public_configuration_has_a_docstring(path, name):
    """CleanRL's ``Args`` habit: a string literal right under every field says what it is."""
    tree = ast.parse((REPO / path).read_text())
    (cls,) = [n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == name]
    body = cls.body
    undocumented = [
        node.target.id
        for node, following in zip(body, [*body[1:], None], strict=True)
        if isinstance(node, ast.AnnAssign)
        and not (
            isinstance(following, ast.Expr)
            and isinstance(following.value, ast.Constant)
            and isinstance(following.value.value, str)
        )
    ]
    assert undocumented == []
