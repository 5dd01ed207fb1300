"""The lookalike evidence in the HTML report and on the order map.

The report is parsed with the standard library's :class:`html.parser.HTMLParser`: the
checks read the text of ``<section id="lookalikes">`` and of its tables, not the raw
markup.  The order map must draw each added effect's declared order lines, labelled
with its name.
"""

from __future__ import annotations

import copy
import functools
from html.parser import HTMLParser
from pathlib import Path

import faults as F
import matplotlib
import pytest

matplotlib.use("Agg")

import matplotlib.pyplot as plt
from matplotlib.figure import Figure

from rotor_env.diagnosis import diagnose
from rotor_env.effects import EFFECTS

HEADING = "Told apart from its lookalikes"
VOID = {"br", "img", "meta", "hr", "input", "link", "wbr"}


@functools.cache
def _bow():
    return diagnose(F.bow(1, **F.FAST), model=F.BASE.model, ip=F.BASE.ip)


@functools.cache
def _forcing_2x():
    return diagnose(F.forcing_2x(1, **F.FAST), model=F.BASE.model, ip=F.BASE.ip)


@functools.cache
def _healthy():
    return diagnose(F.healthy(11, **F.FAST), model=F.BASE.model, ip=F.BASE.ip)


@functools.cache
def _rub():
    return diagnose(F.rub(1, **F.FAST), model=F.BASE.model, ip=F.BASE.ip)


@functools.cache
def _stiffer():
    """A healthy rotor 10 % stiffer than its model: a stiffness change, no rub."""
    params = F.BASE.params(None, k=1.1)
    return diagnose(F._run(params, 1, F.NOISE, F.RUN_UP, F.FAST["t_end"], F.FAST["dt"]), model=F.BASE.model,
                    ip=F.BASE.ip)


CASES = {"shaft_bow": _bow, "misalignment": _forcing_2x, "rub": _rub}


class _Report(HTMLParser):
    """The text of ``<section id="lookalikes">``, its headings, its tables (by class, as
    rows of cell texts), and every h2 heading of the page in order."""

    def __init__(self) -> None:
        super().__init__()
        self.depth = 0
        self.seen = False
        self.text: list[str] = []
        self.h2: list[str] = []
        self.h3: list[str] = []
        self.tables: dict[str, list[list[list[str]]]] = {}
        self._heading: tuple[str, list[str]] | None = None
        self._table: list[list[str]] | None = None
        self._row: list[str] | None = None
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if self.depth:
            self.depth += tag not in VOID
        elif tag == "section" and a.get("id") == "lookalikes":
            self.depth, self.seen = 1, True
        if tag in ("h2", "h3"):
            self._heading = (tag, [])
        if not self.depth:
            return
        if tag == "table":
            self._table = []
            self.tables.setdefault(a.get("class") or "", []).append(self._table)
        elif tag == "tr" and self._table is not None:
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = []

    def handle_endtag(self, tag):
        if self._heading is not None and tag == self._heading[0]:
            text = " ".join("".join(self._heading[1]).split())
            (self.h2 if tag == "h2" else self.h3 if self.depth else []).append(text)
            self._heading = None
        if tag in ("td", "th") and self._cell is not None:
            self._row.append(" ".join("".join(self._cell).split()))
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self._table.append(self._row)
            self._row = None
        elif tag == "table":
            self._table = None
        if self.depth and tag not in VOID:
            self.depth -= 1

    def handle_data(self, data):
        if self.depth:
            self.text.append(data)
        for buf in (self._cell, self._heading[1] if self._heading else None):
            if buf is not None:
                buf.append(data)

    @property
    def section(self) -> str:
        return " ".join(" ".join(self.text).split())


def _parse(path: Path) -> tuple[_Report, str]:
    text = path.read_text(encoding="utf-8")
    p = _Report()
    p.feed(text)
    p.close()
    return p, text


@pytest.mark.parametrize("effect", sorted(CASES))
def test_report_tells_the_added_effect_from_its_lookalikes(effect, tmp_path):
    d = CASES[effect]()
    assert d.missing == [effect]
    ev = next(e for e in d.lookalikes if e["effect"] == effect)
    assert ev["lookalikes"], "the library declares lookalikes for this effect"
    rep, text = _parse(d.report(tmp_path / f"{effect}.html"))
    assert rep.seen and HEADING in rep.h2
    # after the verdict, before the figures
    assert text.index("id='verdict'") < text.index("id='lookalikes'") < text.index("<img")
    assert rep.h2.index("Verdict") < rep.h2.index(HEADING) < rep.h2.index("Compare")
    assert effect in rep.h3 and effect in rep.section
    # its declared orders, in words
    for o in EFFECTS[effect].orders:
        assert f"{o:+d}x {'forward' if o > 0 else 'backward'}" in rep.section
    # the residual's order lines before adding it, and the main order by speed band
    (orders,) = rep.tables["lookalike-orders"]
    assert orders[0][:2] == ["order", "whirl"]
    top = ev["residual_orders"][0]
    assert orders[1][:2] == [f"{top['order']:g}x", top["direction"]]
    (speed,) = rep.tables["lookalike-speed"]
    assert len(speed) == 1 + len(ev["residual_by_speed"]) > 1
    assert all(row[1] != "-" for row in speed[1:])
    # every lookalike, with its status (and its test where it was ranked)
    (status,) = rep.tables["lookalike-status"]
    assert status[0][:2] == ["lookalike", "status"]
    rows = {row[0]: row for row in status[1:]}
    assert set(rows) == {lk["effect"] for lk in ev["lookalikes"]}
    for lk in ev["lookalikes"]:
        assert rows[lk["effect"]][1] == " ".join(lk["status"].split())
        if lk.get("log10_p") is not None:
            assert rows[lk["effect"]][2] == f"{lk['log10_p']:.4g}"


def test_bow_lookalike_is_unbalance_already_in_the_model(tmp_path):
    rep, _ = _parse(_bow().report(tmp_path / "bow.html"))
    (status,) = rep.tables["lookalike-status"]
    rows = {row[0]: row[1] for row in status[1:]}
    assert set(rows) == {"unbalance"}
    assert "in the model already" in rows["unbalance"]


def test_misalignment_lookalikes_are_ranked_below(tmp_path):
    rep, _ = _parse(_forcing_2x().report(tmp_path / "forcing_2x.html"))
    (status,) = rep.tables["lookalike-status"]
    rows = {row[0]: row for row in status[1:]}
    assert set(rows) == {"asymmetry", "breathing_crack", "nonlinear_stiffness"}
    for name, row in rows.items():  # each was tested: a status, its log10 p, energy drop and orders
        assert row[1] and all(cell != "-" for cell in row[2:]), row
        assert row[3].endswith("%")
        assert row[4].startswith("0x static" if EFFECTS[name].orders[0] == 0 else "+")


def test_rub_told_from_stiffness_by_where_it_acts(tmp_path):
    """rub vs stiffness / quadratic stiffness: the evidence is where the misfit sits.  The
    starting model refitted to the samples below the scanned clearance leaves noise only
    (a stiffness change would act there too), above it many times the floor; the JSON
    (``candidates[*].evidence.lookalikes.acts_where``), the summary and the report say so."""
    import json

    d = _rub()
    assert d.missing == ["rub"]
    out = json.loads(d.to_json())
    cand = next(c for c in out["candidates"] if c["effect"] == "rub")
    assert cand["scan"]["values"]["rub_clearance"] == pytest.approx(0.04, rel=0.02)  # faults.RUB_GAP
    ev = cand["evidence"]["lookalikes"]
    assert {lk["effect"] for lk in ev["lookalikes"]} == {"stiffness", "nonlinear_stiffness"}
    where = ev["acts_where"]
    refit = where["starting_model_refitted_over_floor"]
    assert refit["elsewhere"] < 1.5 < 10.0 < refit["where_it_acts"], refit
    assert where["acts_above_amplitude"] == pytest.approx(where["scanned"]["rub_clearance"], rel=0.02)
    assert 0.0 < where["active_share"] < 0.9 and where["sweep"] == "run-up"
    # the contact starts near the critical 1/sqrt(1 - ip) = 1.2 of the run-up
    assert 0.9 < where["first_contact"]["speed"] < 1.2
    assert 0.0 <= where["backward_1x_share"] <= 1.0 and 0.0 <= where["half_order_share"] <= 1.0
    assert "rub_clearance = 0.04" in d.summary() and "refitted to the samples" in d.summary()
    rep, _ = _parse(d.report(tmp_path / "rub.html"))
    assert "Scanned: rub_clearance = 0.04" in rep.section and "refitted to the others" in rep.section


def test_stiffness_change_is_not_a_rub():
    """A stiffness change acts at every amplitude: named ``stiffness``; the rub, its
    lookalike, is reported with its status and the clearance its scan tried."""
    d = _stiffer()
    assert d.missing == ["stiffness"], (d.missing, d.rejected)
    ev = next(e for e in d.lookalikes if e["effect"] == "stiffness")
    rows = {lk["effect"]: lk for lk in ev["lookalikes"]}
    assert "rub" in rows and rows["rub"]["status"]
    assert "acts_where" not in ev


def test_healthy_report_has_no_lookalike_section(tmp_path):
    d = _healthy()
    assert d.missing == [] and not any(ev["lookalikes"] for ev in d.lookalikes)
    rep, text = _parse(d.report(tmp_path / "healthy.html"))
    assert not rep.seen and HEADING not in rep.h2 and HEADING not in text


def test_lookalike_strings_are_escaped(tmp_path):
    hostile = "<script>alert(1)</script>"
    d = copy.copy(_forcing_2x())  # shallow: the list is replaced, not mutated
    ev = dict(d.lookalikes[0])
    ev["lookalikes"] = [*ev["lookalikes"], {"effect": hostile, "status": "<i>x</i> & more"}]
    d.lookalikes = [ev]
    rep, text = _parse(d.report(tmp_path / "hostile.html"))
    assert "<script" not in text.lower() and "<i>x</i>" not in text
    (status,) = rep.tables["lookalike-status"]
    assert [hostile, "<i>x</i> & more"] == status[-1][:2]
    assert status[-1][2:] == ["-", "-", "-"]


def _labels(fig: Figure) -> list[str]:
    out = []
    for ax in fig.axes:
        out += ax.get_legend_handles_labels()[1]
        out += [t.get_text() for t in ax.texts]
    return out


@pytest.mark.parametrize("effect", sorted(CASES))
def test_order_map_marks_the_added_effect_orders(effect):
    d = CASES[effect]()
    fig = d.plot_order_map()
    try:
        assert isinstance(fig, Figure)
        ax = fig.axes[0]
        assert ax.get_xlabel() and ax.get_ylabel()
        assert all(a.get_ylabel() for a in fig.axes)  # the colour bar keeps its unit too
        handles, labels = ax.get_legend_handles_labels()
        assert effect in labels
        line = handles[labels.index(effect)]
        assert list(line.get_xdata()) == [EFFECTS[effect].orders[0]] * 2  # a vertical line at its order
        drawn = {round(float(ln.get_xdata()[0]), 6) for ln in ax.lines
                 if ln.get_color() == line.get_color() and len(ln.get_xdata())}
        assert drawn == {float(o) for o in EFFECTS[effect].orders}
        # the lookalikes are drawn too, in another style
        for lk in [x for x in EFFECTS[effect].lookalikes if x not in d.missing][:2]:
            assert f"{lk} (lookalike)" in _labels(fig)
    finally:
        plt.close(fig)


def test_order_map_survives_an_effect_without_orders():
    d = copy.copy(_bow())
    no_orders = next(name for name, eff in EFFECTS.items() if not eff.orders)
    d.missing = [no_orders]
    d.lookalikes = [{"effect": no_orders, "declared_orders": [], "lookalikes": []}]
    fig = d.plot_order_map()
    try:
        labels = _labels(fig)
        assert any(lab.startswith(no_orders) for lab in labels)
        assert fig.axes[0].get_xlabel() and fig.axes[0].get_ylabel()
    finally:
        plt.close(fig)
    fig = _healthy().plot_order_map()  # nothing added: no legend, the plain map
    try:
        assert fig.axes[0].get_legend() is None and fig.axes[0].get_xlabel()
    finally:
        plt.close(fig)
