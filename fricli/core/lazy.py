"""Modules imported on first use, so that importing fricli stays fast.

``pa = lazy.module("pyarrow")`` at the top of a module reads like ``import pyarrow as pa``,
but pyarrow is imported only when an attribute of ``pa`` is first looked up. The command
line starts in a fraction of a second this way; commands that need pyarrow, scipy or
matplotlib pay for them when they run.
"""

from __future__ import annotations

import importlib


class LazyModule:
    """Stands in for the module ``name`` and imports it on the first attribute access."""

    def __init__(self, name: str):
        self._name = name
        self._module = None

    def __getattr__(self, attr: str):
        module = self._module
        if module is None:
            module = self._module = importlib.import_module(self._name)
        return getattr(module, attr)

    def __repr__(self) -> str:
        state = "imported" if self._module is not None else "not imported yet"
        return f"<lazy module {self._name!r} ({state})>"


def module(name: str) -> LazyModule:
    return LazyModule(name)
