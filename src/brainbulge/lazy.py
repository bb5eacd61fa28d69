"""Package namespaces whose names load on first use (PEP 562).

A package's ``__init__`` that maps public names to the submodules defining them gets its
``__getattr__`` and ``__dir__`` here, so that importing one light submodule (the CLI's parser
reads option declarations) does not pull in NGSolve or the meshing stack.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def lazy_names(package: str, namespace: dict[str, Any], where: dict[str, str]
               ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package``: the public name ``n`` is loaded from the
    submodule ``where[n]`` on first use and kept in ``namespace`` (the package's globals)."""

    def __getattr__(name: str) -> Any:
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{where[name]}"), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted([*namespace, *where])

    return __getattr__, __dir__
