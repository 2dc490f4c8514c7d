"""Hostile configuration files get a one-line error naming the file, fast and small (issue
48, item 5): an alias bomb, deep nesting, a non-UTF-8 file, an oversized file."""

import time

import pytest

from lonlib.config import load_config

BOMB = "\n".join(
    ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    + [
        f"{chr(98 + i)}: &{chr(98 + i)} [" + ", ".join([f"*{chr(97 + i)}"] * 9) + "]"
        for i in range(8)
    ]
    + ["note: *i"]
)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (BOMB, "alias to a list or mapping is not allowed"),
        ("note: " + "[" * 100_000 + "]" * 100_000, "nested more than 32 levels deep"),
        ("runs: 2\nnote: caf\xe9\n".encode("latin-1"), r"not UTF-8 text \(byte 0xe9 at position"),
        ("note: '" + "x" * 1_100_000 + "'\n", "more than a configuration needs"),
    ],
    ids=["alias-bomb", "deep", "latin-1", "huge"],
)
def test_a_hostile_configuration_is_refused_in_one_line_naming_the_file(tmp_path, text, message):
    path = tmp_path / "hostile.yaml"
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    start = time.perf_counter()
    with pytest.raises(ValueError, match=message) as refused:
        load_config(path)
    assert time.perf_counter() - start < 10
    assert str(refused.value).startswith(f"{path}: ")
    assert "\n" not in str(refused.value)


def test_a_scalar_alias_is_still_fine(tmp_path):
    path = tmp_path / "anchors.yaml"
    path.write_text("runs: &n 2\nmax_local_searches: *n\n")
    config = load_config(path)
    assert config.runs == 2 and config.max_local_searches == 2


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda config: config.update(tolerance=float("nan")), "tolerance"),
        (lambda config: config.update(a_future_key=1), "a_future_key"),
    ],
    ids=["nan-tolerance", "future-key"],
)
def test_a_manifest_with_a_bad_stored_value_names_the_manifest_and_the_field(
    tmp_path, change, message
):
    import json
    import shutil
    from pathlib import Path

    from lonlib.storage import CorruptDataError
    from lonlib.storage.layout import stored_config

    root = Path(__file__).resolve().parents[2] / "data" / "reference"
    folder = tmp_path / "copy"
    folder.mkdir()
    shutil.copy(root / "manifest.json", folder / "manifest.json")
    manifest = json.loads((folder / "manifest.json").read_text())
    change(manifest["config"])
    (folder / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(CorruptDataError, match=message) as refused:
        stored_config(folder)
    assert str(refused.value).startswith(f"{folder / 'manifest.json'}: ")
