"""Field checks shared by the frozen configuration dataclasses.

Every message names the field and what is allowed, so bad input fails before any compute.
"""

from __future__ import annotations

import math
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml


def check_field_types(config: Any) -> None:
    """Each field holds its annotated kind: integers are integers (not bools), numbers are
    finite numbers, text is text, flags are bools. Other annotations are left to the class."""
    for f in fields(config):
        value = getattr(config, f.name)
        kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
        if kind == "int":
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ValueError(f"{f.name} must be an integer, got {value!r}")
        elif kind == "float":
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise ValueError(f"{f.name} must be a number, got {value!r}")
            if not is_finite(value):
                raise ValueError(f"{f.name} must be a finite number, got {value!r}")
        elif kind == "str":
            if not isinstance(value, str):
                raise ValueError(f"{f.name} must be text, got {value!r}")
        elif kind == "bool" and not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{f.name} must be true or false, got {value!r}")


def is_finite(value: float) -> bool:
    """``math.isfinite`` that also answers (False) for integers too large for a float."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def check_range(
    name: str,
    value: float,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
) -> None:
    """``low <= value <= high`` (``low < value`` when ``low_open``); either bound optional.
    NaN is in no range."""
    if value != value:
        raise ValueError(f"{name} must be a number, got {value!r}")
    too_low = low is not None and (value <= low if low_open else value < low)
    too_high = high is not None and value > high
    if too_low or too_high:
        left = "(" if low_open else "["
        lo = "-inf" if low is None else _number(low)
        hi = "inf" if high is None else _number(high)
        raise ValueError(f"{name} must be in {left}{lo}, {hi}], got {value!r}")


def check_keys(section: str, values: dict, config_class: type) -> None:
    """Every key of ``values`` is a field of ``config_class``; unknown keys are named."""
    known = {f.name for f in fields(config_class)}
    unknown = sorted((repr(k) for k in values if k not in known), key=str)
    if unknown:
        raise ValueError(
            f"unknown {section} key(s) [{', '.join(unknown)}]; allowed: {sorted(known)}"
        )


def check_choice(name: str, value: Any, allowed: tuple) -> None:
    """``value`` must be one of ``allowed``."""
    if value not in allowed:
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}")


def check_name(name: Any) -> None:
    """A configuration's name: letters, digits, '-' or '_' (it names folders and files)."""
    if not isinstance(name, str) or not name.replace("-", "").replace("_", "").isalnum():
        raise ValueError(f"name must be letters, digits, '-' or '_', got {name!r}")


MAX_CONFIG_BYTES = 1_000_000
"""A configuration file larger than this is refused (a real one is a few kB)."""
MAX_CONFIG_DEPTH = 32
"""How deeply a configuration's lists and mappings may nest."""


class _BoundedLoader(yaml.SafeLoader):
    """PyYAML's safe loader with a nesting bound, and no alias (``*name``) to a list or
    mapping: such aliases let a few lines expand without bound (a billion-laughs file)."""

    depth = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            node = super().compose_node(parent, index)
            if not isinstance(node, yaml.ScalarNode):
                mark = node.start_mark
                raise ValueError(
                    f"line {mark.line + 1}: a YAML alias to a list or mapping is not allowed in "
                    "a configuration (it can expand without bound); write the values out"
                )
            return node
        self.depth += 1
        try:
            if self.depth > MAX_CONFIG_DEPTH:
                mark = self.peek_event().start_mark
                raise ValueError(
                    f"line {mark.line + 1}: nested more than {MAX_CONFIG_DEPTH} levels deep"
                )
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1


def read_yaml_mapping(path: Path, what: str) -> dict[str, Any]:
    """The mapping in a YAML configuration file, ``name`` defaulting to the file's stem;
    ValueError naming the file if it is larger than :data:`MAX_CONFIG_BYTES`, not UTF-8, not
    valid YAML, nested deeper than :data:`MAX_CONFIG_DEPTH`, uses an alias to a list or
    mapping, or is not a mapping of ``what`` keys."""
    path = Path(path)
    data = path.read_bytes()
    if len(data) > MAX_CONFIG_BYTES:
        raise ValueError(
            f"{path}: {len(data):,} bytes, more than a configuration needs (at most "
            f"{MAX_CONFIG_BYTES:,})"
        )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ValueError(
            f"{path}: not UTF-8 text (byte 0x{data[error.start]:02x} at position {error.start})"
        ) from None
    try:
        values = yaml.load(text, Loader=_BoundedLoader) or {}
    except yaml.YAMLError as error:
        raise ValueError(f"{path}: not valid YAML ({error})") from None
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
    if not isinstance(values, dict):
        raise ValueError(f"{path}: expected a mapping of {what} keys")
    values.setdefault("name", path.stem)
    return values


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() and abs(value) < 1e15 else f"{value:g}"
