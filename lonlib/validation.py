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
    """Integers must be integers (not bools), numbers must be finite numbers."""
    for f in fields(config):
        value = getattr(config, f.name)
        if f.type in ("int", int):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ValueError(f"{f.name} must be an integer, got {value!r}")
        elif f.type in ("float", float):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise ValueError(f"{f.name} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"{f.name} must be finite, got {value!r}")


def check_range(
    name: str,
    value: float,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
) -> None:
    """``low <= value <= high`` (``low < value`` when ``low_open``); either bound optional."""
    too_low = low is not None and (value <= low if low_open else value < low)
    too_high = high is not None and value > high
    if too_low or too_high:
        left = "(" if low_open else "["
        lo = "-inf" if low is None else _number(low)
        hi = "inf" if high is None else _number(high)
        raise ValueError(f"{name} must be in {left}{lo}, {hi}], got {value!r}")


def check_choice(name: str, value: Any, allowed: tuple) -> None:
    """``value`` must be one of ``allowed``."""
    if value not in allowed:
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}")


def check_name(name: Any) -> None:
    """A configuration's name: letters, digits, '-' or '_' (it names folders and files)."""
    if not isinstance(name, str) or not name.replace("-", "").replace("_", "").isalnum():
        raise ValueError(f"name must be letters, digits, '-' or '_', got {name!r}")


def read_yaml_mapping(path: Path, what: str) -> dict[str, Any]:
    """The mapping in a YAML configuration file, ``name`` defaulting to the file's stem;
    ValueError naming the file if it is not valid YAML or not a mapping of ``what`` keys."""
    try:
        values = yaml.safe_load(Path(path).read_text()) or {}
    except yaml.YAMLError as error:
        raise ValueError(f"{path}: not valid YAML ({error})") from None
    if not isinstance(values, dict):
        raise ValueError(f"{path}: expected a mapping of {what} keys")
    values.setdefault("name", Path(path).stem)
    return values


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() and abs(value) < 1e15 else f"{value:g}"
