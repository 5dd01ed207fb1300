"""The diagnosis of one file, as ``rotor-id diagnose`` and ``rotor-id batch`` run it.

The engine both commands share (the CLI parses the arguments, :mod:`rotor_env.fleet`
maps this over a fleet of recordings): :func:`diagnose_file` picks the reader and the
diagnosis from the kind of file, :func:`model_list` reads a ``--model`` text,
:func:`inertia_ratio` checks an ``--ip`` value, :func:`table_amplitude_unit` an ``--amp-unit``,
and :func:`argparse_type` turns either into an argparse type whose errors are usage errors.
Errors are :class:`ValueError` with a message that names the option and the value.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Sequence


def inertia_ratio(text: str) -> float:
    """``--ip``: the inertia ratio ``I_p/I_t`` as a number in [0, 1)."""
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and 0 <= value < 1):
        raise ValueError(f"{text!r}: the inertia ratio I_p/I_t must be a number in [0, 1)")
    return value


def table_amplitude_unit(text: str) -> str:
    """``--amp-unit``: a table's amplitude unit, optionally with its measure (``um``, ``mil pp``,
    ``um-rms``: :func:`~rotor_env.measurements.vectors.amplitude_unit`), returned as given."""
    from .measurements.vectors import amplitude_unit

    amplitude_unit(text)
    return text


def argparse_type(check: Callable[[str], object]) -> Callable[[str], object]:
    """``check`` as an argparse ``type=``: its :class:`ValueError` message becomes the usage
    error (argparse would otherwise print only "invalid value")."""
    def parse(text: str):
        try:
            return check(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parse.__name__ = check.__name__
    return parse


def model_list(text: str | None, default: Sequence[str]) -> list[str]:
    """``--model A,B``: the effect names (each a registered effect), or ``default`` when None."""
    if text is None:
        return list(default)
    names = [m.strip() for m in text.split(",") if m.strip()]
    if not names:
        raise ValueError("--model needs at least one effect name")
    from .effects import get_effect

    for n in names:
        get_effect(n)
    return names


def diagnose_file(file, *, model: str | None = None, ip: float | None = None, alpha: float = 0.05,
                  slow_roll: float | None = None, vectors: bool = False, rig=None, amp_unit: str = "um",
                  phase: str = "lag", progress: bool = False):
    """Diagnose one file as ``rotor-id diagnose`` does (shared by ``diagnose`` and ``batch``).

    ``model``: the comma-separated ``--model`` text (None: the default model of the kind of
    file).  A dimensionless measurement file unless ``vectors`` (an order-tracked table)
    or ``rig`` (a rig file path or a loaded :class:`~rotor_env.measurements.rig.Rig`:
    raw waveforms, or the table's probes with ``vectors``).
    """
    from .diagnosis.from_rig import diagnose_rig
    from .diagnosis.from_vectors import VECTOR_CANDIDATES, VECTOR_MODEL, diagnose_vectors
    from .diagnosis.model import DEFAULT_MODEL
    from .measurements.rig import load_rig
    from .measurements.vectors import load_vector_table
    from .measurements.waveforms import load_waveforms
    from .progress import step

    step(f"reading {file}")
    if isinstance(rig, (str, bytes)) or hasattr(rig, "__fspath__"):
        rig = load_rig(rig)
    if not vectors and rig is None:
        from .diagnosis import LIBRARY_CANDIDATES, diagnose
        from .measurements.files import load_measurements

        meas = load_measurements(file)
        names = model_list(model, DEFAULT_MODEL)
        return diagnose(meas, names, candidates=[c for c in LIBRARY_CANDIDATES if c not in names], ip=ip,
                        alpha=alpha, slow_roll=slow_roll, progress=progress)
    if vectors:
        # one plane: the probes see one orbit from their angles; probes in several planes see
        # different amplitudes of the mode: each is then fitted on its own (no common geometry)
        angles = ({p.name: math.degrees(p.angle) for p in rig.probes}
                  if rig is not None and len(rig.plane_names) == 1 else None)
        table = load_vector_table(file, amp_unit=amp_unit, phase=phase, angles=angles)
        names = model_list(model, VECTOR_MODEL) if model else list(VECTOR_MODEL)
        ip = rig.ip if rig is not None else (ip if ip is not None else 0.0)
        step("1X table: fitting the run-up model's synchronous response, trying each effect")
        return diagnose_vectors(table, ip=ip, model=names, alpha=alpha, phase=phase,
                                candidates=[c for c in VECTOR_CANDIDATES if c not in names])
    record = load_waveforms(file, rig)
    names = model_list(model, DEFAULT_MODEL)
    return diagnose_rig(record, names, alpha=alpha, progress=progress)
