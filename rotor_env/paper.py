"""Zhou & Shi (2004), numerical study: the four cases re-run with the online estimator.

Table-1 rotor and the variants ``h = 0``, ``D = 0``, ``k12 = 0``; rotor at rest,
``phi_ddot = 0.01``, ``t`` in [0, 400], ``dt = 0.01``; Gaussian noise of variance 1e-4
added to ``y``; the paper's regressors (Eq. 10: tau, D, c, k21, k12, k03, h; first
equation); the paper's start (zero parameters, residual energies 0.01 = ``prior``).
Significance: the nested partial F of each term (term ``i`` added to the first
``i - 1``), alpha = 0.05, read at ``t = 200`` and ``t = 300``.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from identifier import nested_f

from .params import RotorParams
from .regression import build_regression
from .simulator import simulate

__all__ = ["CASES", "PAPER_TABLE2", "PaperCase", "run_case", "run_paper"]

TERMS = ("tau", "D", "c", "k21", "k12", "k03", "h")
NOISE_STD = 0.01  # variance 1e-4 on y
PRIOR = 0.01
READ_TIMES = (200.0, 300.0)

CASES: dict[str, tuple[str, dict[str, float]]] = {
    "1": ("Table 1", {}),
    "2": ("h = 0", {"h": 0.0}),
    "3": ("D = 0", {"D": 0.0}),
    "4": ("k12 = 0", {"k12": 0.0}),
}

# The paper's Table 2: estimate, F, significant (None: the paper's "—").
PAPER_TABLE2: dict[str, dict[str, tuple[float, float | None, bool | None]]] = {
    "1": {"tau": (0.0201, None, None), "D": (0.0321, 809.73, True), "c": (0.0292, 0.52079, None),
          "k21": (0.0426, 129.67, True), "k12": (0.0297, 67.693, True), "k03": (0.0205, 67.733, True),
          "h": (0.0098, 4709.8, True)},
    "2": {"tau": (0.0201, None, None), "D": (0.0320, 723.98, True), "c": (0.0285, 1292.2, True),
          "k21": (0.0421, 99.92, True), "k12": (0.0273, 24.502, True), "k03": (0.0214, 93.005, True),
          "h": (0.0002, 1.7157, False)},
    "3": {"tau": (0.0201, None, None), "D": (0.0022, 1.2566, False), "c": (0.0294, 2.4175, None),
          "k21": (0.0430, 315.6, True), "k12": (0.0296, 134.83, True), "k03": (0.0206, 182.84, True),
          "h": (0.0099, 5242.6, True)},
    "4": {"tau": (0.0199, None, None), "D": (0.0292, 1837.5, True), "c": (0.0286, 10.473, None),
          "k21": (0.0392, 301.07, True), "k12": (0.0020, 0.023104, False), "k03": (0.0195, 195.92, True),
          "h": (0.0098, 5319.1, True)},
}


@dataclass
class PaperCase:
    """One case's online identification: histories over time and the readings."""

    name: str
    label: str
    params: RotorParams
    t: np.ndarray            # sample times
    theta: np.ndarray        # (m, 2) th_x, th_y
    speed: np.ndarray
    coefficients: np.ndarray  # (m, 7) online estimates of the full model
    F: np.ndarray            # (m, 7) nested partial F (F[:, 0]: tau vs nothing)
    log10_p: np.ndarray      # (m, 7)
    standard_errors: dict[float, np.ndarray]

    def truth(self) -> dict[str, float]:
        v = self.params.values
        return {"tau": v["tau"], "D": v["D"], "c": v["c"], "k21": v["k21"], "k12": v["k12"],
                "k03": v["k03"], "h": v["h"]}

    def reading(self, t: float, alpha: float = 0.05) -> dict[str, dict]:
        k = int(np.searchsorted(self.t, t - 1e-9))
        out = {}
        for j, name in enumerate(TERMS):
            row = {"estimate": float(self.coefficients[k, j]),
                   "standard_error": float(self.standard_errors[t][j])}
            if name != "tau":
                row["F"] = float(self.F[k, j])
                row["significant"] = bool(self.log10_p[k, j] < np.log10(alpha))
            out[name] = row
        return out


def run_case(name: str, seed: int = 0, *, progress: bool = False) -> PaperCase:
    """Simulate case ``name`` ("1".."4") and identify it online."""
    label, changes = CASES[name]
    params = RotorParams().replace(**changes)
    meas = simulate(params, t_end=400.0, dt=0.01, run_up=0.01, progress=progress)
    from .progress import step

    step(f"case {name}: online identification")
    reg = build_regression(meas, "paper", ip=params.ip, equation="first")
    rng = np.random.default_rng(seed)
    y = reg.y + rng.normal(0.0, NOISE_STD, size=reg.y.shape)
    est = reg.estimator(prior=PRIOR)
    n = len(TERMS)
    ses: dict[float, np.ndarray] = {}
    # Stream the data up to each reading time to take standard errors there, then on.
    hist_e, hist_c, hist_m = [], [], []
    start = 0
    for t_read in (*READ_TIMES, np.inf):
        stop = int(np.searchsorted(reg.t, t_read - 1e-9)) + 1 if np.isfinite(t_read) else len(y)
        h = est.update_many(reg.X[start:stop], y[start:stop], return_energies=True, return_coefficients=n)
        hist_e.append(h.energies)
        hist_c.append(h.coefficients[n])
        hist_m.append(h.effective_samples)
        if np.isfinite(t_read):
            ses[t_read] = est.standard_errors()
        start = stop
    E = np.concatenate(hist_e)
    F, _, lp, _, _, _ = nested_f(E, np.concatenate(hist_m))
    return PaperCase(
        name=name, label=label, params=params, t=reg.t, theta=np.column_stack([meas.theta_x, meas.theta_y]),
        speed=meas.phi_dot, coefficients=np.concatenate(hist_c), F=F, log10_p=lp, standard_errors=ses,
    )


def table2(cases: dict[str, PaperCase], t: float = 300.0) -> dict[str, dict]:
    """Table 2 at time ``t`` in the JSON layout of ``rotor-id paper --json``."""
    out = {}
    for name, case in cases.items():
        r = case.reading(t)
        out[name] = {k: {kk: v[kk] for kk in ("estimate", "F", "significant") if kk in v} for k, v in r.items()}
    return out


def _fmt_sig(s: bool | None) -> str:
    return "—" if s is None else ("Yes" if s else "No")


def write_tables(cases: dict[str, PaperCase], out: Path) -> tuple[Path, Path]:
    """Table 2 (ours at t = 200 and 300, and the paper's) as Markdown and CSV."""
    md = ["# Table 2 reproduced (online recursive QR, nested partial F, alpha = 0.05)", ""]
    rows = []
    for name, case in cases.items():
        truth = case.truth()
        md.append(f"## Case {name}: {case.label}")
        md.append("")
        md.append("| term | truth | paper est. | paper F | paper sig. | "
                  + " | ".join(f"est. t={t:g} | F t={t:g} | sig. t={t:g}" for t in READ_TIMES) + " |")
        md.append("|---" * (5 + 3 * len(READ_TIMES)) + "|")
        readings = {t: case.reading(t) for t in READ_TIMES}
        for term in TERMS:
            p_est, p_F, p_sig = PAPER_TABLE2[name][term]
            cells = [term, f"{truth[term]:.4g}", f"{p_est:.4f}", "" if p_F is None else f"{p_F:.5g}",
                     "" if term == "tau" else _fmt_sig(p_sig)]
            row = {"case": name, "term": term, "truth": truth[term], "paper_estimate": p_est,
                   "paper_F": p_F, "paper_significant": p_sig}
            for t in READ_TIMES:
                r = readings[t][term]
                cells += [f"{r['estimate']:.4f} ± {r['standard_error']:.1e}",
                          "" if "F" not in r else f"{r['F']:.5g}",
                          "" if "F" not in r else _fmt_sig(r["significant"])]
                row[f"estimate_t{t:g}"] = r["estimate"]
                row[f"standard_error_t{t:g}"] = r["standard_error"]
                row[f"F_t{t:g}"] = r.get("F")
                row[f"significant_t{t:g}"] = r.get("significant")
            md.append("| " + " | ".join(cells) + " |")
            rows.append(row)
        md.append("")
    md_path, csv_path = out / "table2.md", out / "table2.csv"
    md_path.write_text("\n".join(md))
    with open(csv_path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return md_path, csv_path


def plot_figures(cases: dict[str, PaperCase], out: Path) -> list[Path]:
    """Fig. 3 (response), Fig. 4 (parameter tracks, truth dashed), Fig. 5 (significance)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    fig, axes = plt.subplots(len(cases), 1, figsize=(9, 2.2 * len(cases)), sharex=True)
    for ax, (name, case) in zip(np.atleast_1d(axes), cases.items(), strict=True):
        ax.plot(case.t, case.theta[:, 0], lw=0.4, label=r"$\theta_x$")
        ax.plot(case.t, case.theta[:, 1], lw=0.4, label=r"$\theta_y$", alpha=0.7)
        ax.plot(case.t, np.hypot(case.theta[:, 0], case.theta[:, 1]), "k", lw=1, label=r"$|\theta|$")
        ax.set_ylabel(f"case {name}\n({case.label})")
    np.atleast_1d(axes)[0].legend(loc="upper right", ncol=3, fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel("t (dimensionless); speed = 0.01 t")
    fig.suptitle("Fig. 3 — response of the accelerating rotor")
    fig.tight_layout()
    paths.append(out / "fig3_response.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(len(cases), 1, figsize=(9, 2.6 * len(cases)), sharex=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, (name, case) in zip(np.atleast_1d(axes), cases.items(), strict=True):
        truth = case.truth()
        for j, term in enumerate(TERMS):
            ax.plot(case.t, case.coefficients[:, j], color=colors[j % len(colors)], lw=1, label=term)
            ax.axhline(truth[term], color=colors[j % len(colors)], ls="--", lw=0.8)
        ax.set_ylim(-0.02, 0.07)
        ax.set_ylabel(f"case {name}\n({case.label})")
    np.atleast_1d(axes)[0].legend(loc="upper left", ncol=7, fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel("t")
    fig.suptitle("Fig. 4 — online parameter estimates (truth dashed)")
    fig.tight_layout()
    paths.append(out / "fig4_parameters.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(len(cases), 1, figsize=(9, 2.4 * len(cases)), sharex=True)
    for ax, (name, case) in zip(np.atleast_1d(axes), cases.items(), strict=True):
        for j, term in enumerate(TERMS[1:], start=1):
            ax.plot(case.t, np.maximum(-case.log10_p[:, j], 1e-3), color=colors[j % len(colors)], lw=1,
                    label=term)
        ax.axhline(-np.log10(0.05), color="k", ls=":", lw=1)
        ax.set_yscale("log")
        ax.set_ylim(1e-2, None)
        ax.set_ylabel(f"case {name}\n" + r"$-\log_{10} p$")
    np.atleast_1d(axes)[0].legend(loc="upper left", ncol=6, fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel("t")
    fig.suptitle(r"Fig. 5 — nested partial-F significance over time ($\alpha$ = 0.05 dotted)")
    fig.tight_layout()
    paths.append(out / "fig5_significance.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)
    return paths


def run_paper(out: Path | None = None, seed: int = 0, progress: bool = False) -> dict[str, PaperCase]:
    """All four cases; with ``out``, write the figures and Table 2 there."""
    from .progress import step

    cases = {}
    for name in CASES:
        step(f"case {name} of {len(CASES)}")
        cases[name] = run_case(name, seed=seed, progress=progress)
    if out is not None:
        step("figures and Table 2")
        out.mkdir(parents=True, exist_ok=True)
        plot_figures(cases, out)
        write_tables(cases, out)
        (out / "table2_t300.json").write_text(json.dumps(table2(cases), indent=2))
    return cases
