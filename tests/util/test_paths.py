"""Notebook paths mean one folder whatever the working directory."""

from pathlib import Path

from lonlib.util.paths import project_path, project_root


def make_project(root: Path) -> Path:
    (root / "data").mkdir(parents=True)
    (root / "notebooks" / "data").mkdir(parents=True)  # a stray folder must not win
    (root / "pyproject.toml").write_text("[project]\nname = 'x'\n")
    return root


def test_relative_paths_are_read_from_the_project_root(tmp_path):
    root = make_project(tmp_path / "clone")
    for cwd in (root, root / "notebooks", root / "notebooks" / "data"):
        assert project_root(cwd) == root.resolve()
        assert project_path("data/quick", cwd) == root.resolve() / "data" / "quick"


def test_absolute_paths_and_folders_outside_a_project_are_kept(tmp_path):
    root = make_project(tmp_path / "clone")
    assert project_path(tmp_path / "elsewhere", root / "notebooks") == tmp_path / "elsewhere"
    outside = tmp_path / "loose"
    outside.mkdir()
    assert project_path("data/quick", outside) == outside.resolve() / "data" / "quick"
    # pyproject.toml without data/ (another project) is not this project's root
    (outside / "pyproject.toml").write_text("")
    assert project_root(outside / ".") == outside.resolve()
    (outside / "sub").mkdir()
    assert project_root(outside / "sub") == (outside / "sub").resolve()


def test_default_start_is_the_working_directory(tmp_path, monkeypatch):
    root = make_project(tmp_path / "clone")
    monkeypatch.chdir(root / "notebooks")
    assert project_path("data/quick") == root.resolve() / "data" / "quick"
