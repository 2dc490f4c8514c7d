"""lonlib's public surface: each subpackage's ``__all__`` names what a user calls, and what a
user reads (the notebooks' code cells, the docs' Python examples, ``tests/mutants.py``) uses those
names only. No alias modules of before the subpackages remain."""

import ast
import importlib
import json
import re
from pathlib import Path

import pytest

import lonlib

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "lonlib"
SUBPACKAGES = sorted(p.parent.name for p in PACKAGE.glob("*/__init__.py"))
# the whole public surface, every ``__init__``'s ``__all__`` together (507 names before 0.2)
MOST_PUBLIC_NAMES = 250
MOST_NAMES_PER_SUBPACKAGE = 30


def user_code() -> list[tuple[str, str]]:
    """(where, code) of every piece of code a user reads."""
    found = []
    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        cells = json.loads(path.read_text())["cells"]
        for i, cell in enumerate(c for c in cells if c["cell_type"] == "code"):
            lines = "".join(cell["source"]).splitlines()
            code = "\n".join(line for line in lines if not line.lstrip().startswith(("%", "!")))
            found.append((f"{path.relative_to(ROOT)}#{i}", code))
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        blocks = re.findall(r"```python\n(.*?)```", path.read_text(), re.S)
        found += [(f"{path.relative_to(ROOT)}#{i}", block) for i, block in enumerate(blocks)]
    found.append(("tests/mutants.py", (ROOT / "tests" / "mutants.py").read_text()))
    return found


def public(module: str, name: str) -> bool:
    """Whether ``from module import name`` takes a public name: one in the ``__all__`` of
    ``lonlib`` or of the subpackage that ``module`` lies in, or a module itself."""
    parts = module.split(".")
    package = importlib.import_module(".".join(parts[:2]))
    if name in package.__all__:
        return True
    try:
        importlib.import_module(f"{module}.{name}")
    except ImportError:
        return False
    return True


def used_names(code: str) -> list[tuple[str, str]]:
    """(module, name) of every ``from lonlib... import name`` and ``lonlib.x.name`` in code."""
    found = []
    for node in ast.walk(ast.parse(code)):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "lonlib":
            found += [(node.module, alias.name) for alias in node.names]
        elif isinstance(node, ast.Attribute):
            chain = []
            while isinstance(node, ast.Attribute):
                chain.append(node.attr)
                node = node.value
            if isinstance(node, ast.Name) and node.id == "lonlib":
                dotted = ["lonlib", *reversed(chain)]
                found.append((".".join(dotted[:-1]), dotted[-1]))
    return found


USES = [(where, module, name) for where, code in user_code() for module, name in used_names(code)]


def test_the_user_code_is_found():
    places = {where.split("#")[0] for where, _, _ in USES}
    assert {"README.md", "notebooks/sample_lon.ipynb", "notebooks/analyse_lon.ipynb"} <= places
    assert len(USES) > 30


@pytest.mark.parametrize(
    ("where", "module", "name"), USES, ids=[f"{w}:{m}.{n}" for w, m, n in USES]
)
def test_user_code_uses_public_names_only(where, module, name):
    assert public(module, name), f"{where}: {module}.{name} is not in an __all__"


def test_the_public_surface_is_small_and_sorted():
    packages = [lonlib] + [importlib.import_module(f"lonlib.{name}") for name in SUBPACKAGES]
    for package in packages:
        assert len(package.__all__) <= MOST_NAMES_PER_SUBPACKAGE, package.__name__
        assert not [name for name in package.__all__ if name.startswith("_") and name[1] != "_"]
    assert sum(len(package.__all__) for package in packages) <= MOST_PUBLIC_NAMES


def test_no_alias_modules_remain():
    """The top level holds the package's entry points only (the layout moved everything else
    into the subpackages, and the aliases that kept the old names are gone): the ``lonlib``
    command (``lonlib.cli``, a package of its verbs) and the papermill engine."""
    top = sorted(path.name for path in PACKAGE.glob("*.py"))
    assert top == ["__init__.py", "__main__.py", "notebook_run.py"]
    assert (PACKAGE / "cli" / "__init__.py").is_file()
    for path in PACKAGE.rglob("*.py"):
        assert "sys.modules[__name__]" not in path.read_text(), path
