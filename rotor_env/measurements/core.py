"""Measurements of a run: the ten columns the simulator records (and files hold)."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

__all__ = ["ANGLE_CHANNELS", "COLUMNS", "Measurements"]

#: Column order of every measurement array and file (dimensionless units, docs/PHYSICS.md 1.4).
COLUMNS: tuple[str, ...] = (
    "t",
    "phi",
    "phi_dot",
    "phi_ddot",
    "theta_x",
    "theta_y",
    "theta_x_dot",
    "theta_y_dot",
    "theta_x_ddot",
    "theta_y_ddot",
)
#: The six inclination channels (the ones a noise model perturbs by default).
ANGLE_CHANNELS: tuple[str, ...] = COLUMNS[4:]


class Measurements:
    """A ``(m, 10)`` array of samples with the columns :data:`COLUMNS`.

    Columns read as attributes (``meas.theta_x``) or items (``meas["theta_x"]``).
    """

    __slots__ = ("data", "estimated", "source")

    def __init__(self, data: np.ndarray, source: str | None = None, estimated: tuple[str, ...] = ()) -> None:
        data = np.asarray(data, dtype=float)
        if data.ndim != 2 or data.shape[1] != len(COLUMNS):
            raise ValueError(f"measurements must have shape (m, {len(COLUMNS)}), got {data.shape}")
        self.data = data
        self.source = source
        #: the columns estimated from others (rates and accelerations differentiated from the
        #: angles): the diagnosis decides on the output error when those angles are noisy
        self.estimated = tuple(estimated)

    def __len__(self) -> int:
        return self.data.shape[0]

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[:, COLUMNS.index(name)]
        except ValueError:
            raise KeyError(f"unknown column {name!r}; columns are {', '.join(COLUMNS)}") from None

    def __getattr__(self, name: str) -> np.ndarray:
        if name in COLUMNS:
            return self.data[:, COLUMNS.index(name)]
        raise AttributeError(name)

    @property
    def dt(self) -> float:
        t = self.data[:, 0]
        return float(t[1] - t[0]) if len(t) > 1 else float("nan")

    def slice_time(self, t_start: float | None = None, t_stop: float | None = None) -> Measurements:
        t = self.data[:, 0]
        mask = np.ones(len(t), dtype=bool)
        if t_start is not None:
            mask &= t >= t_start
        if t_stop is not None:
            mask &= t <= t_stop
        return Measurements(self.data[mask], self.source, self.estimated)

    def with_noise(self, std: float | Mapping[str, float], seed: int | None = None) -> Measurements:
        """A copy with independent Gaussian noise (per channel std), reproducible by ``seed``."""
        if isinstance(std, Mapping):
            stds = dict(std)
        else:
            stds = dict.fromkeys(ANGLE_CHANNELS, std)
        rng = np.random.default_rng(seed)
        out = self.data.copy()
        for name, s in stds.items():
            if name not in COLUMNS:
                raise ValueError(f"noise: unknown channel {name!r}; channels are {', '.join(COLUMNS)}")
            s = float(s)
            if not (np.isfinite(s) and s >= 0):
                raise ValueError(f"noise std for {name!r} must be a finite number >= 0, got {s!r}")
            if s > 0:
                j = COLUMNS.index(name)
                out[:, j] += rng.normal(0.0, s, size=len(out))
        return Measurements(out, self.source, self.estimated)

    def to_file(self, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
        """Write CSV (or Parquet if the name ends in ``.parquet``); never overwrites silently.

        The file is written to a temporary name and moved into place when complete
        (:func:`rotor_env.outputs.atomic_write`): an interrupted write leaves no
        truncated file that would load cleanly.
        """
        from ..outputs import atomic_write

        path = Path(path)
        if path.suffix == ".parquet":
            import pyarrow as pa
            import pyarrow.parquet as pq

            table = pa.table({c: self.data[:, i] for i, c in enumerate(COLUMNS)})
            return atomic_write(path, lambda tmp: pq.write_table(table, tmp), overwrite=overwrite)
        return atomic_write(
            path,
            lambda tmp: np.savetxt(tmp, self.data, delimiter=",", header=",".join(COLUMNS), comments="", fmt="%.17g"),
            overwrite=overwrite,
        )
