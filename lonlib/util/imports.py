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
        raise ValueError(f"{field}: cannot import {module_name!r} ({error})") from None
    except Exception as error:  # the user's module raised while it was imported
        raise ValueError(
            f"{field}: importing {module_name!r} raised {type(error).__name__}: {error}"
        ) from None
    function = getattr(module, function_name, None)
    if not callable(function):
        raise ValueError(f"{field}: {module_name!r} has no function {function_name!r}")
    return function  # type: ignore[no-any-return]


__all__ = ["import_function"]
