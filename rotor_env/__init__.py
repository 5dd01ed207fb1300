"""rotor_env — the accelerating rotor: effects, simulator, Gymnasium environments, CLI.

>>> from rotor_env import simulate, RotorParams, diagnose
>>> meas = simulate(RotorParams(), t_end=50.0)
>>> len(meas)
5001
"""

from .diagnosis import Diagnosis, Model, diagnose, fit
from .effects import EFFECTS, PACKAGE_EFFECTS, Effect, Parameter, get_effect, register_effect
from .measurements import COLUMNS, Measurements
from .measurements.files import MeasurementError, load_measurements
from .params import Crack, RotorParams
from .regression import Regression, RegressionSpec, build_regression
from .simulator import RunUp, SimulationError, Simulator, free_run, simulate
from .wrappers import IdentificationWrapper, VectorIdentificationWrapper

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
    # gymnasium is a dependency (the wrapper above imports it); entry points are strings
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
