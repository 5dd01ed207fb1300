"""Balancing from 1X vectors: influence coefficients, correction weights, honest misfit.

:func:`balance` reads a campaign (RUNS.yaml, :mod:`.runs`) and its 1X table with a
``run`` column, fits the influence coefficients by weighted least squares
(:mod:`.influence`), gives every run's total unbalance and the reference's correction
(:mod:`.correction`) with first-order intervals, and checks where the linear model fails
(:mod:`.misfit`).  ``rotor-id balance`` is its command line (:mod:`.cli`); docs/BALANCING.md
the conventions.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

# The names load on first use (PEP 562): ``rotor-id --version`` and the command line's parser
# (which imports :mod:`.cli`) do not pay for scipy.
_LAZY = {
    "BalanceData": ".runs", "BalanceError": ".runs", "Campaign": ".runs", "load_campaign": ".runs",
    "read_balance_table": ".runs", "stack_tables": ".runs",
    "BalanceResult": ".result", "InfluenceFit": ".influence",
    "balance": ".campaign", "balance_data": ".campaign", "model_based_unbalance": ".campaign",
}

if TYPE_CHECKING:
    from .campaign import balance, balance_data, model_based_unbalance
    from .influence import InfluenceFit
    from .result import BalanceResult
    from .runs import (
        BalanceData,
        BalanceError,
        Campaign,
        load_campaign,
        read_balance_table,
        stack_tables,
    )

__all__ = ["BalanceData", "BalanceError", "BalanceResult", "Campaign", "InfluenceFit", "balance", "balance_data",
           "load_campaign", "model_based_unbalance", "read_balance_table", "stack_tables"]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
