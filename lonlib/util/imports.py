"""A function named ``module:function`` in a configuration (a user's own code, imported)."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def import_function(name: str, field: str) -> Callable[..., Any]:
    """The function ``module:function`` names, imported now (ValueError naming ``field``
    when the module does not import, raises while imported, or has no such function)."""
    module_name, _, function_name = name.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise ValueError(f"{field}: cannot import {module_name!r} ({_one_line(error)})") from None
    except (Exception, SystemExit) as error:  # the user's module raised (or exited) on import
        raise ValueError(
            f"{field}: importing {module_name!r} raised {type(error).__name__}: {_one_line(error)}"
        ) from None
    function = getattr(module, function_name, None)
    if not callable(function):
        raise ValueError(f"{field}: {module_name!r} has no function {function_name!r}")
    return function  # type: ignore[no-any-return]


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split())


__all__ = ["import_function"]
