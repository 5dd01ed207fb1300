"""The HTML of every result: one page shell, one figure embedder, one escaping.

Every report (a diagnosis, a rig or 1X-vector diagnosis, a balancing, a monitoring run)
builds its body here and writes it with :func:`write_page`, so the pages share one look
and one rule: every string from data or user input goes through :func:`esc`, and a
figure is embedded as a PNG (:func:`figure_tag`) so the page is one self-contained file.
"""

from __future__ import annotations

import base64
import html
import io
import os
from pathlib import Path

#: the look every page shares; a page adds its own rules with ``extra_style``
STYLE = ("body{font-family:sans-serif;max-width:1000px;margin:auto;padding:1em;color:#222}"
         "table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:3px 8px}"
         "img{max-width:100%}pre{background:#f4f4f4;padding:.5em}")


def esc(x) -> str:
    """``x`` as text, HTML-escaped (quotes too): for every string from data or user input."""
    return html.escape(str(x))


def png_base64(fig, *, dpi: int = 100) -> str:
    """Matplotlib figure ``fig`` as base64 PNG text; the figure is closed (its memory freed)."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def figure_tag(fig, alt: str, *, dpi: int = 100) -> str:
    """``fig`` as an ``<img>`` carrying its PNG inline (``alt`` escaped)."""
    return f'<img alt="{esc(alt)}" src="data:image/png;base64,{png_base64(fig, dpi=dpi)}">'


def figure_tags(figures: dict, *, heading: int | None = None) -> str:
    """Every figure of ``figures`` (name -> figure) as an ``<img>``, each after an
    ``<h{heading}>`` naming it where ``heading`` is given."""
    head = (lambda name: f"<h{heading}>{esc(name)}</h{heading}>") if heading else (lambda name: "")
    return "".join(head(name) + figure_tag(fig, name) for name, fig in figures.items())


def page(title: str, body: str, *, extra_style: str = "") -> str:
    """A whole HTML document: the shared head (``title`` escaped, :data:`STYLE` and
    ``extra_style``) around ``body`` (HTML, already escaped where it holds data)."""
    return ('<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
            f"<title>{esc(title)}</title><style>{STYLE}{extra_style}</style></head>"
            f"<body>\n{body}\n</body></html>\n")


def write_page(path: str | os.PathLike, title: str, body: str, *, extra_style: str = "",
               overwrite: bool = False) -> Path:
    """Write :func:`page` to ``path`` atomically (an existing file only with ``overwrite``)."""
    from .outputs import atomic_write_text

    return atomic_write_text(path, page(title, body, extra_style=extra_style), overwrite=overwrite)
