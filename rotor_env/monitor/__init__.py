"""On-line monitoring: a measurement stream in, the identified model and alarms out (issue 15).

:class:`Monitor` (Python API, state saved to ``.npz``), :class:`StreamReader` (chunks of a
file, a followed file or stdin), the sequential test's design in :mod:`.detector`, the
command ``rotor-id monitor`` in :mod:`.cli`.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

# Imported on first use (PEP 562): the command line builds its parser from ``.cli`` without
# loading the monitor's compiled core.
_LAZY: dict[str, str] = {
    "Monitor": ".core", "MonitorConfig": ".core",
    "CusumDesign": ".detector", "cusum_arl0": ".detector", "cusum_threshold": ".detector",
    "simulate_arl": ".detector",
    "StreamReader": "..measurements.stream", "iter_chunks": "..measurements.stream",
}

if TYPE_CHECKING:
    from ..measurements.stream import StreamReader, iter_chunks
    from .core import Monitor, MonitorConfig
    from .detector import CusumDesign, cusum_arl0, cusum_threshold, simulate_arl

__all__ = ["CusumDesign", "Monitor", "MonitorConfig", "StreamReader", "cusum_arl0", "cusum_threshold",
           "iter_chunks", "simulate_arl"]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
