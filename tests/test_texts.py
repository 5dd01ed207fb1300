"""What the commands print carries units and reads as text (issue 25, item 6)."""

from __future__ import annotations

import io
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def test_piped_monitor_view_prints_lines_not_glued_text_or_dict_reprs():
    from rich.console import Console

    from rotor_env.monitor.live import LiveView

    view = LiveView("-")
    buf = io.StringIO()
    view.console = Console(file=buf, width=100)  # a pipe: not a terminal
    assert not view.console.is_terminal
    monitor = SimpleNamespace(effects=("asymmetry",), threshold=5.4)
    view.start(monitor)
    status = {"event": "status", "t": 260.0, "speed": 2.6, "noise_floor": 1e-4,
              "coefficients": {"asymmetry": {"D": 0.0396}}, "significant": {"asymmetry": True},
              "cusum": {"asymmetry": 0.0}}
    alarm = {"event": "changed", "effect": "asymmetry", "t_alarm": 253.99, "t_onset": 250.0,
             "value_before": {"D": 0.03}, "value_after": {"D": 0.0396}}
    view.show(status)
    view.show(alarm)
    view.stop()
    view.print_summary({"samples": 40001, "t": 400.0, "alarms": 1, "events": [alarm]})
    text = buf.getvalue()
    assert "{'" not in text, text  # no Python dict repr
    assert "D = 0.03 -> D = 0.0396" in text
    assert re.search(r"so\s+far\n40001 samples", text), text  # the table, then the summary on its own line
    first_alarm = text.index("asymmetry changed at t = 253.99")
    assert first_alarm < text.index("┏"), "piped, the alarm is printed when it comes, before the final table"


def test_rig_summary_gives_the_rms_in_the_rigs_unit():
    """The rig summary: one verdict first, then the waveforms' output error (residual and the
    probes' noise floor in the rig's unit, from a real fit), the 1X vectors as a part."""
    import math

    from rotor_env.diagnosis.from_rig import RigDiagnosis
    from rotor_env.diagnosis.oe_diagnosis import diagnose_output_error
    from rotor_env.diagnosis.output_error import ShootingGrid
    from rotor_env.params import RotorParams
    from rotor_env.simulator import RunUp, Simulator

    p = RotorParams(ip=0.0, effects=("stiffness", "unbalance", "viscous_damping"),
                    values={"tau": 0.005, "beta": 0.3, "c": 0.05})
    m = Simulator(p).run(t_end=300.0, dt=0.04, run_up=RunUp(rate=0.005, speed0=0.4))
    rng = np.random.default_rng(0)
    noise = 5e-4  # 0.5 um in the model's length unit (1 mm)
    grid = ShootingGrid.from_arrays(m.t, m.phi, m.phi_dot, m.theta_x + rng.normal(0, noise, len(m.t)),
                                    m.theta_y + rng.normal(0, noise, len(m.t)), 0.0, noise_std=noise)
    diag = diagnose_output_error(grid, ("unbalance", "viscous_damping"), ("shaft_bow",), unit_scale=1000.0,
                                 unit="um")
    rig = SimpleNamespace(model="translation", amp_unit="um", to_metres=lambda v: v * 1e-6, source="rig.yaml")
    record = SimpleNamespace(rig=rig, source="run.csv", rpm=np.array([300.0, 3000.0]), notes=(),
                             t=np.array([0.0, 12.0]), phi=np.array([0.0, 2000.0]))
    # the 1X vectors' fit passed the critical (the two parts' natural frequencies are not compared)
    after = SimpleNamespace(rotor_criticals=[{"rpm": 1650.0, "damping_ratio": 0.025}], w_ref=172.8)
    vectors = SimpleNamespace(to_dict=lambda: {"criticals": []}, summary=lambda: "1X summary", missing=(), undecidable={},
                              after=after)
    rd = RigDiagnosis(record=record, vectors=vectors, diagnosis=diag, w_ref=172.8)
    text = rd.summary()
    assert text.splitlines()[1].startswith(f"VERDICT: {diag.verdict}")
    d = diag.to_dict()
    assert f"residual {d['rms_after']:.4g} um" in text and f"noise floor {d['noise_floor']:.4g} um" in text
    assert math.isclose(d["noise_floor"], 0.5, rel_tol=1e-9)  # the given probe noise, in um
    assert text.index("waveforms (output error)") < text.index("part: 1X vectors")


def test_evaluate_table_and_json_name_the_units():
    from agents.evaluation import METRIC_UNITS, METRICS, format_table

    result = {"agents": {"ramp": dict.fromkeys(METRICS, 1.0)}}
    table = format_table(result)
    header = table.splitlines()[0]
    for k in METRICS:
        assert f"{k} ({METRIC_UNITS[k]})" in header
    assert "units: rad = disk inclination" in table


def test_readme_effect_list_names_every_library_effect():
    import rotor_env

    text = (ROOT / "README.md").read_text(encoding="utf-8")
    para = text[text.index("Effect names:"):]
    para = para[: para.index("\n\n")]
    missing = [n for n in rotor_env.PACKAGE_EFFECTS if f"`{n}`" not in para]
    assert not missing, f"README's effect list omits {missing}"
