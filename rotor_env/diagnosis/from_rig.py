"""Diagnosis of a rig recording (probes and keyphasor in engineering units).

1. The probes are order-tracked per revolution and the 1X vectors diagnosed
   (:mod:`.from_vectors`): critical speeds in rpm, damping ratios, the natural frequency
   ``w_ref`` — and probe runout, which is then subtracted from the waveforms (unless the
   rig description asked for slow-roll compensation, done on loading).
2. The waveforms are made dimensionless with ``t' = t w_ref``
   (:meth:`~rotor_env.measurements.waveforms.RigRecord.to_measurements`) and diagnosed
   like any record (:func:`.workflow.diagnose`): every library effect, the onset scan,
   the checks and the verdict, with the rig's inertia ratio (``ip = 0`` for one plane).
3. Results come back in engineering units: critical speeds (rpm), damping ratios, the
   equation-error RMS as an equivalent static deflection in the rig's unit (the
   dimensionless moment times the model's length unit), the unbalance response.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

from ..measurements.rig import SPEED_UNITS
from ..measurements.waveforms import LENGTH_UNIT, RigRecord
from ..results import Result
from .from_vectors import VectorDiagnosis, diagnose_vectors
from .model import DEFAULT_MODEL, LIBRARY_CANDIDATES
from .synchronous import RUNOUT
from .workflow import diagnose

__all__ = ["RigDiagnosis", "diagnose_rig"]

#: slow roll: revolutions below this fraction of the first critical
SLOW_ROLL_FRACTION = 0.3


@dataclass
class RigDiagnosis(Result):
    """The waveform diagnosis and the 1X-vector diagnosis of one rig recording."""

    record: RigRecord
    vectors: VectorDiagnosis
    diagnosis: object  #: Diagnosis or NotIdentifiableResult (dimensionless)
    w_ref: float  #: rad/s

    @property
    def unit_scale(self) -> float:
        """Dimensionless displacement -> the rig's reporting unit."""
        if self.record.rig.model != "translation":
            return 1e6  # rad -> urad
        return LENGTH_UNIT / self.record.rig.to_metres(1.0)

    @property
    def rms_unit(self) -> str:
        return "urad" if self.record.rig.model != "translation" else self.record.rig.amp_unit

    def to_dict(self) -> dict:
        d = dict(self.diagnosis.to_dict())
        s = self.unit_scale
        for key in ("rms_before", "rms_after", "noise_floor"):
            if d.get(key) is not None:
                d[f"{key}_dimensionless"] = d[key]
                d[key] = d[key] * s
        vd = self.vectors.to_dict()
        vd["unbalance"] = self.vectors.unbalance(self.record.rig.mass_kg)
        d.update({
            "kind": "rig",
            "rig": self.record.rig.source,
            "model_kind": self.record.rig.model,
            "rms_unit": f"{self.rms_unit} (equation error as an equivalent static deflection)",
            "criticals": vd["criticals"],
            "natural_frequency_rpm": self.w_ref / SPEED_UNITS["rpm"],
            "time_unit_s": 1.0 / self.w_ref,
            "vectors": {k: vd[k] for k in ("missing", "verdict", "rms_before", "rms_after", "noise_floor",
                                           "amplitude_unit", "method", "physical", "unbalance")},
            "notes": [*d.get("notes", []), *self.record.notes],
        })
        return d

    def summary(self) -> str:
        lines = [f"rig recording {self.record.source} ({self.record.rig.model}, "
                 f"{self.record.rpm.min():.0f}-{self.record.rpm.max():.0f} rpm)"]
        for c in self.vectors.to_dict()["criticals"]:
            lines.append(f"critical speed {c['rpm']:.1f} rpm, damping ratio {c['damping_ratio']:.4f}")
        lines.append(f"time unit of the model: 1/{self.w_ref:.6g} s (natural frequency "
                     f"{self.w_ref / SPEED_UNITS['rpm']:.1f} rpm)")
        lines.append("")
        lines.append("1X vectors: " + self.vectors.summary().replace("\n", "\n  "))
        lines.append("")
        lines.append("waveforms: " + self.diagnosis.summary().replace("\n", "\n  "))
        return "\n".join(lines)

    def report(self, path, *, overwrite: bool = False):
        """The waveform diagnosis's report (in s and rpm), with the 1X vectors' section first."""
        import html

        head = (f"<h2>Rig recording</h2><p>{html.escape(str(self.record.source))}: {self.record.rig.model} model, "
                f"{self.record.rpm.min():.0f}&ndash;{self.record.rpm.max():.0f} rpm; the model's time unit "
                f"1/{self.w_ref:.6g} s (natural frequency {self.w_ref / SPEED_UNITS['rpm']:.1f} rpm).</p>"
                + self.vectors.html_section(level=3) + "<h2>Waveforms</h2>")
        if hasattr(self.diagnosis, "_verdict_html"):
            return self.diagnosis.report(path, overwrite=overwrite, preamble=head)
        return self.diagnosis.report(path, overwrite=overwrite)

    def save_figures(self, folder, *, overwrite: bool = True):
        return self.diagnosis.save_figures(folder, overwrite=overwrite)

    @property
    def verdict(self) -> str:
        return self.diagnosis.verdict


def diagnose_rig(
    record: RigRecord,
    model: Sequence[str] = DEFAULT_MODEL,
    *,
    candidates: Sequence[str] | None = None,
    alpha: float = 0.05,
    progress: bool = False,
) -> RigDiagnosis:
    """Diagnose a rig recording (see the module docstring)."""
    ip = record.rig.ip
    vd = diagnose_vectors(record.vectors((1,)), ip=ip, alpha=alpha)
    if RUNOUT in vd.missing and record.rig.slow_roll_rpm is None:
        # runout seen in the 1X vectors: compensate it as field engineers do, from the
        # slow-roll revolutions (well below the critical, where the unbalance response is
        # a few per cent of the eccentricity) -- not from the 1X fit, which an effect the
        # 1X model cannot carry (a crack, a rub) would bias
        crit = vd.to_dict()["criticals"]
        below = SLOW_ROLL_FRACTION * (crit[0]["rpm"] if crit else vd.after.w_ref / SPEED_UNITS["rpm"])
        if (record.rpm < below).sum() > 0 and float(record.rpm.min()) < below:
            try:
                record = record.compensate_runout(below_rpm=below)
            except ValueError as exc:
                record = replace(record, notes=(*record.notes, f"runout not compensated: {exc}"))
        else:
            record = replace(record, notes=(*record.notes, f"runout seen in the 1X vectors, but the run has no "
                                                          f"slow roll below {below:.0f} rpm to take it from"))
    w_ref = vd.after.w_ref
    meas = record.to_measurements(w_ref)
    cands = [c for c in (candidates if candidates is not None else LIBRARY_CANDIDATES) if c not in model]
    result = diagnose(meas, list(model), candidates=cands, ip=ip, alpha=alpha, progress=progress)
    if not math.isfinite(w_ref):  # pragma: no cover - fit_vectors returns finite values
        raise RuntimeError("no natural frequency identified")
    if hasattr(result, "time_scale"):
        # the figures in s and rpm: t_model = time_scale * t_file, the file's time in s
        result.time_scale = float(result.time_scale) * w_ref
        result.time_unit = "s"
        result.amplitude_unit = "mm" if record.rig.model == "translation" else "rad"
    return RigDiagnosis(record, vd, result, w_ref)
