"""The verdict in the HTML report: word, sentence, what is left, the candidates turned
down, the notes, and every string from data or user input escaped.

The report is parsed with the standard library's :class:`html.parser.HTMLParser`: the
checks read the text of the ``<section id="verdict">`` and of its tables, not the raw
markup, so they hold whatever the layout's details.
"""

from __future__ import annotations

import copy
import functools
from html.parser import HTMLParser
from pathlib import Path

import faults as F
import matplotlib

matplotlib.use("Agg")

from rotor_env.diagnosis import diagnose

HOSTILE = "<script>alert(1)</script>"
VOID = {"br", "img", "meta", "hr", "input", "link", "wbr"}


@functools.cache
def _outside_the_library():
    return diagnose(F.forcing_3x(1, **F.FAST), model=F.BASE.model, ip=F.BASE.ip)


@functools.cache
def _healthy():
    return diagnose(F.healthy(11, **F.FAST), model=F.BASE.model)


class _Report(HTMLParser):
    """The verdict section's text, its word and notes, and every table (by class, as rows
    of cell texts; ``in_verdict``: the classes of the tables inside the verdict section)."""

    def __init__(self) -> None:
        super().__init__()
        self.depth = 0                 # nesting inside <section id="verdict">, 0 outside
        self.verdict_text: list[str] = []
        self.verdict_word: str | None = None
        self.tables: dict[str, list[list[str]]] = {}
        self.in_verdict: set[str] = set()
        self.notes: list[str] = []
        self.all_text: list[str] = []
        self._table: str | None = None
        self._row: list[str] | None = None
        self._cell: list[str] | None = None
        self._word: list[str] | None = None
        self._li: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if self.depth:
            self.depth += tag not in VOID
        elif tag == "section" and a.get("id") == "verdict":
            self.depth = 1
        if tag == "table":
            self._table = a.get("class") or ""
            self.tables.setdefault(self._table, [])
            if self.depth:
                self.in_verdict.add(self._table)
        elif tag == "tr" and self._table is not None:
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = []
        elif tag == "p" and self.depth and "verdict-word" in (a.get("class") or ""):
            self._word = []
        elif tag == "li" and self.depth:
            self._li = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.tables[self._table].append(self._row)
            self._row = None
        elif tag == "table":
            self._table = None
        elif tag == "p" and self._word is not None:
            self.verdict_word = "".join(self._word).strip()
            self._word = None
        elif tag == "li" and self._li is not None:
            self.notes.append("".join(self._li).strip())
            self._li = None
        if self.depth and tag not in VOID:
            self.depth -= 1

    def handle_data(self, data):
        self.all_text.append(data)
        if self.depth:
            self.verdict_text.append(data)
        for buf in (self._cell, self._word, self._li):
            if buf is not None:
                buf.append(data)

    @property
    def section(self) -> str:
        return " ".join(" ".join(self.verdict_text).split())


def _parse(path: Path) -> tuple[_Report, str]:
    text = path.read_text(encoding="utf-8")
    p = _Report()
    p.feed(text)
    p.close()
    return p, text


def test_unexplained_run_shows_verdict_orders_and_rejected(tmp_path):
    d = _outside_the_library()
    assert d.verdict in ("unexplained", "partly_explained")
    rep, text = _parse(d.report(tmp_path / "forcing_3x.html"))
    assert rep.verdict_word == d.verdict
    assert "explains" in rep.section or "library does not hold" in rep.section  # the sentence
    assert f"{d.rms_ratio_after:.3g}" in rep.section  # final RMS over the floor
    # the top order line of the unexplained residual: a 3x forcing whirls forward at 3x
    assert {"orders", "bands", "rejected"} <= rep.in_verdict
    orders = rep.tables["orders"]
    assert orders[0][:2] == ["order", "whirl"]
    assert orders[1][:2] == ["3x", "forward"]
    assert orders[1][2].endswith("%") and float(orders[1][2].rstrip(" %")) > 50
    bands = rep.tables["bands"][1:]
    assert len(bands) == len(d.unexplained["bands"]) > 0
    # every candidate turned down is named in the rejected table, with a rule
    assert d.rejected
    rejected = {row[0]: row[1:] for row in rep.tables["rejected"][1:]}
    for r in d.rejected:
        assert r["effect"] in rejected
        assert rejected[r["effect"]] == [r["rule"], str(r["round"])]
    # the verdict comes before the figures; the EIV bias column is there when it was removed
    assert text.index("id='verdict'") < text.index("<img")
    assert d.after.eiv_bias is not None
    coef = rep.tables["coefficients"]
    assert "bias removed" in coef[0][-1] and len(coef) == 1 + len(d.after.columns)
    assert all(len(row) == 4 for row in coef)


def test_healthy_run_is_explained_without_order_lines(tmp_path):
    d = _healthy()
    assert d.verdict == "explained"
    rep, _ = _parse(d.report(tmp_path / "healthy.html"))
    assert rep.verdict_word == "explained"
    assert "explains the data" in rep.section
    assert "orders" not in rep.tables and "bands" not in rep.tables
    assert "rejected" in rep.in_verdict
    # the ip estimate the diagnosis made is reported as a note
    assert any(n.startswith("ip estimated from the data") for n in rep.notes)


def test_strings_from_data_and_users_are_escaped(tmp_path):
    d = copy.copy(_outside_the_library())  # a shallow copy: the lists below are replaced, not mutated
    d.source = HOSTILE
    d.notes = [*d.notes, "<b>x</b>"]
    d.rejected = [*d.rejected, {"effect": HOSTILE, "rule": "<i>rule</i> & more"}]
    rep, text = _parse(d.report(tmp_path / "hostile.html"))
    assert "<script" not in text.lower()
    assert "<b>x</b>" not in text and "<i>rule</i>" not in text
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in text
    # the parsed (unescaped) text carries the names as the user wrote them
    assert "<b>x</b>" in rep.notes
    assert [HOSTILE, "<i>rule</i> & more"] in rep.tables["rejected"]
    assert HOSTILE in "".join(rep.all_text)


def test_hostile_user_effect_name_is_escaped(tmp_path):
    """A registered user effect with a hostile name, turned down by the diagnosis."""
    from rotor_env.diagnosis.model import effect_from_function
    from rotor_env.effects import EFFECTS, register_effect

    def useless(phi, phid, phidd, th_x, th_y, w_x, w_y, ip):  # a column of pure phase noise
        return (0.0 * th_x + 1e-9 * (phi % 1.0),), (0.0 * th_y,)

    name = "<script>alert(1)</script>"
    register_effect(effect_from_function(useless, name))
    try:
        d = diagnose(F.healthy(11, **F.FAST), model=F.BASE.model, ip=F.BASE.ip, candidates=[name])
        assert name not in d.model
        text = d.report(tmp_path / "user.html").read_text(encoding="utf-8")
    finally:
        EFFECTS.pop(name, None)
    assert "<script" not in text.lower()
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in text


def test_not_identifiable_report_states_it(tmp_path):
    res = diagnose(F.zeros(), model=F.BASE.model, ip=0.3)
    assert res.verdict == "not_identifiable"
    rep, _ = _parse(res.report(tmp_path / "none.html"))
    body = " ".join("".join(rep.all_text).split())
    assert "not_identifiable" in body
    assert res.reason in body
