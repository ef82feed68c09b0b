"""The one HTML renderer of redrive's reports (the evaluation report, the A/B comparison): small
builders of a self-contained page — inline CSS, tables, figures as PNG ``data:`` URIs (:func:`png`
turns a matplotlib figure into them), no JavaScript, no network reference.

Every text that enters the page goes through :func:`esc` (``html.escape`` with quotes), so a
name like ``<script>`` from a run is shown, never run.  Builders return ``Markup`` (a ``str``
subclass meaning "already HTML"); anything else is escaped when combined.
"""

from __future__ import annotations

import base64
import contextlib
import html
import io
import math
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "Markup",
    "details",
    "esc",
    "figure",
    "fmt_number",
    "img",
    "page",
    "paragraph",
    "png",
    "section",
    "table",
]


class Markup(str):
    """A string that is already HTML (built here from escaped parts)."""

    __slots__ = ()


def esc(value: object) -> Markup:
    """``value`` as HTML text: ``Markup`` unchanged, anything else ``str()``-ed and escaped
    (``& < > " '``)."""
    if isinstance(value, Markup):
        return value
    return Markup(html.escape(str(value), quote=True))


def fmt_number(value: float | None, *, digits: int = 4) -> str:
    """``value`` with ``digits`` significant digits; ``n/a`` for None and NaN."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if isinstance(value, bool | int):
        return str(value)
    return f"{value:.{digits}g}"


def _attrs(**attrs: str) -> str:
    return "".join(f' {k.rstrip("_")}="{esc(v)}"' for k, v in attrs.items() if v)


_NUM = ' class="num"'


def table(
    headers: Sequence[object] | None,
    rows: Iterable[Sequence[object]],
    *,
    numeric: Sequence[int] = (),
    class_: str = "",
) -> Markup:
    """A ``<table>`` (no header row when ``headers`` is None); cells of the columns in
    ``numeric`` are right-aligned."""
    num = set(numeric)

    def cls(i: int) -> str:
        return _NUM if i in num else ""

    head = "".join(f"<th{cls(i)}>{esc(h)}</th>" for i, h in enumerate(headers or ()))
    body = []
    for row in rows:
        cells = "".join(f"<td{cls(i)}>{esc(c)}</td>" for i, c in enumerate(row))
        body.append(f"<tr>{cells}</tr>")
    return Markup(
        f"<table{_attrs(class_=class_)}>"
        + (f"<thead><tr>{head}</tr></thead>" if headers is not None else "")
        + f"<tbody>{''.join(body)}</tbody></table>"
    )


def png(fig: Figure, *, dpi: int, tight: bool = False) -> bytes:
    """The PNG bytes of a matplotlib figure (Agg canvas, no pyplot state, no display; no
    timestamp or software in the metadata, so the same figure gives the same bytes); ``tight``
    crops the figure to what is drawn.

    A figure with a layout engine (``layout="constrained"``) is laid out once here, at ``dpi``,
    and saved without it: ``savefig`` would otherwise draw the whole figure twice, once with
    drawing disabled only to run the layout (the same pixels either way; a sixth less work).
    A figure drawn again (:func:`redrive.evaluation.plots.timelines_png`) keeps its Agg canvas,
    so its renderer's cache of text sizes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)  # a figure drawn again keeps its canvas (and text-size cache)
    engine = fig.get_layout_engine()
    if engine is not None and not tight and fig.axes:
        fig.set_dpi(dpi)  # the layout in the pixels savefig draws
        with contextlib.suppress(ValueError):  # as Figure.draw: too small for its decorations
            engine.execute(fig)
        fig.set_layout_engine("none")
    buf = io.BytesIO()
    crop = "tight" if tight else None  # None: the rcParams default, the whole figure
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None}, bbox_inches=crop)
    return buf.getvalue()


def img(png: bytes, *, alt: str, width_px: int = 0) -> Markup:
    """An ``<img>`` holding ``png`` as a base64 ``data:`` URI."""
    data = base64.b64encode(png).decode("ascii")
    width = f' width="{width_px}"' if width_px else ""
    return Markup(f'<img src="data:image/png;base64,{data}" alt="{esc(alt)}"{width}>')


def figure(png: bytes, *, caption: object, alt: str) -> Markup:
    """An image with a caption below it."""
    return Markup(f"<figure>{img(png, alt=alt)}<figcaption>{esc(caption)}</figcaption></figure>")


def details(summary: object, body: object) -> Markup:
    """A collapsed block (``<details>``; opens without JavaScript)."""
    return Markup(f"<details><summary>{esc(summary)}</summary>{esc(body)}</details>")


def section(anchor: str, title: object, *parts: object) -> Markup:
    """``<section id=anchor>`` with an ``<h2>`` title and the parts (escaped unless Markup)."""
    inner = "".join(esc(p) for p in parts)
    return Markup(f'<section id="{esc(anchor)}"><h2>{esc(title)}</h2>{inner}</section>')


def paragraph(text: object, *, class_: str = "") -> Markup:
    return Markup(f"<p{_attrs(class_=class_)}>{esc(text)}</p>")


_CSS = """
body { font: 14px/1.4 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #222;
       margin: 0 auto; padding: 16px 24px; max-width: 1240px; background: #fff; }
h1 { font-size: 22px; margin: 0 0 4px; } h2 { font-size: 18px; border-bottom: 1px solid #ddd;
     padding-bottom: 4px; margin-top: 28px; } h3 { font-size: 15px; margin: 16px 0 6px; }
nav a { margin-right: 14px; color: #1f5fa8; text-decoration: none; }
table { border-collapse: collapse; margin: 6px 0 10px; font-size: 13px; }
th, td { border: 1px solid #ddd; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #f3f4f6; } td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; }
tr.headline td { font-weight: 600; }
.muted { color: #666; } .mono { font-family: ui-monospace, Menlo, Consolas, monospace; }
.grid { display: flex; flex-wrap: wrap; gap: 12px; }
figure { margin: 0; } figcaption { font-size: 12px; color: #444; max-width: 420px; }
details { margin: 4px 0 12px; } summary { cursor: pointer; color: #1f5fa8; }
img { max-width: 100%; } code { background: #f4f4f4; padding: 0 3px; }
.better { color: #187a2f; } .worse { color: #b3261e; }
"""


def page(
    *,
    title: object,
    subtitle: object,
    nav: Sequence[tuple[str, str]],
    body: object,
    heading: object = None,
) -> str:
    """The whole document: inline CSS, a title (the ``<h1>`` is ``heading`` when given), a
    subtitle, links to the sections (``#anchor``) and body."""
    links = "".join(f'<a href="#{esc(anchor)}">{esc(label)}</a>' for anchor, label in nav)
    h1 = title if heading is None else heading
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{esc(title)}</title><style>{_CSS}</style></head>\n"
        f'<body><h1>{esc(h1)}</h1><p class="muted">{esc(subtitle)}</p>'
        f"<nav>{links}</nav>\n{esc(body)}\n</body></html>\n"
    )
