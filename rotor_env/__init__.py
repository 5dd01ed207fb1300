"""rotor_env — the accelerating rotor: effects, simulator, Gymnasium environments, CLI.

>>> from rotor_env import simulate, RotorParams, diagnose
>>> meas = simulate(RotorParams(), t_end=50.0)
>>> len(meas)
5001
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

# The effect library is light (numpy only) and registers the package's effects: imported now.
from .effects import EFFECTS, PACKAGE_EFFECTS, Effect, Parameter, get_effect, register_effect

# Everything else is imported on first use (PEP 562), so that ``rotor-id --version`` or a
# command that only simulates does not pay for scipy, numba and the diagnosis (~2 s).
_LAZY: dict[str, str] = {
    "Diagnosis": ".diagnosis", "Model": ".diagnosis", "diagnose": ".diagnosis", "fit": ".diagnosis",
    "MeasurementError": ".measurements.files", "load_measurements": ".measurements.files",
    "COLUMNS": ".measurements", "Measurements": ".measurements",
    "Crack": ".params", "RotorParams": ".params",
    "Regression": ".regression", "RegressionSpec": ".regression", "build_regression": ".regression",
    "RunUp": ".simulator", "SimulationError": ".simulator", "Simulator": ".simulator",
    "free_run": ".simulator", "simulate": ".simulator",
    "IdentificationWrapper": ".wrappers", "VectorIdentificationWrapper": ".wrappers",
}

if TYPE_CHECKING:  # what static tools and IDEs see
    from .diagnosis import Diagnosis, Model, diagnose, fit
    from .measurements import COLUMNS, Measurements
    from .measurements.files import MeasurementError, load_measurements
    from .params import Crack, RotorParams
    from .regression import Regression, RegressionSpec, build_regression
    from .simulator import RunUp, SimulationError, Simulator, free_run, simulate
    from .wrappers import IdentificationWrapper, VectorIdentificationWrapper


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value  # once: later look-ups are plain attribute reads
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))

__all__ = [
    "COLUMNS",
    "EFFECTS",
    "ENV_IDS",
    "PACKAGE_EFFECTS",
    "Crack",
    "Diagnosis",
    "Effect",
    "IdentificationWrapper",
    "MeasurementError",
    "Measurements",
    "Model",
    "Parameter",
    "Regression",
    "RegressionSpec",
    "RotorParams",
    "RunUp",
    "SimulationError",
    "Simulator",
    "VectorIdentificationWrapper",
    "build_regression",
    "diagnose",
    "fit",
    "free_run",
    "get_effect",
    "load_measurements",
    "register_effect",
    "simulate",
]

#: Gymnasium ids registered on import.
ENV_IDS: tuple[str, ...] = ("rotor_env/RotorRunUp-v0", "rotor_env/RotorBalancing-v0")


def _register_envs() -> None:
    # gymnasium is a dependency; entry points are strings (the environments load on make)
    import gymnasium

    for env_id, module, name in (
        ("rotor_env/RotorRunUp-v0", "run_up", "RotorRunUp"),
        ("rotor_env/RotorBalancing-v0", "balancing", "RotorBalancing"),
    ):
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point=f"rotor_env.envs.{module}:{name}Env",
                vector_entry_point=f"rotor_env.envs.vector:{name}VectorEnv",
            )


_register_envs()
