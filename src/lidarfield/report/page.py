"""HTML building blocks for self-contained pages: every text escaped, images as data URIs."""

from __future__ import annotations

import base64
import html
import math
import os
import struct
from pathlib import Path

from ..plots.png import compact_file, compact_png

STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 1.5em auto; max-width: 1800px;
       padding: 0 1.5em; color: #222; }
h1 { margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; padding-bottom: 0.2em; margin-top: 1.6em; }
.table-box { max-width: 100%; max-height: 90vh; overflow: auto; margin: 0.6em 0; }
table { border-collapse: collapse; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 2px 6px; text-align: right; white-space: nowrap; }
th { background: #f0f0f0; position: sticky; top: 0; white-space: normal; vertical-align: bottom; }
td.text, th.text { text-align: left; } td.prose { white-space: normal; min-width: 16em; }
tr.flag td { background: #fde2e2; color: #a00; font-weight: 600; }
ul.findings li { color: #a00; font-weight: 600; }
td.better { color: #17741b; } td.worse { color: #b00; }
pre { background: #f7f7f7; border: 1px solid #ddd; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
.figures { display: flex; flex-direction: column; gap: 14px; align-items: flex-start; }
.figures.side-by-side { flex-direction: row; }
.figures.side-by-side > figure { flex: 1 1 0; min-width: 0; }
figure { margin: 0; width: 100%; }
figure img { display: block; width: 100%; height: auto; border: 1px solid #ddd; box-sizing: border-box; }
figcaption { font-size: 0.8em; color: #555; }
.hover-spots { position: relative; } .hover-spots > span { position: absolute; }
.hover-spots > span:hover { outline: 2px solid #e00; }
figure.linked { width: auto; border: 1px dashed #bbb; padding: 4px 8px; font-size: 0.9em; }
details > summary { cursor: pointer; font-size: 1.15em; font-weight: 600; margin: 0.6em 0; }
nav { font-size: 0.9em; margin-bottom: 0.5em; }
.budget { background: #fff6d5; border: 1px solid #e0c96a; padding: 0.5em 0.8em; }
.note { color: #666; font-size: 0.9em; } .missing { color: #a00; font-size: 0.85em; }
"""
# A figure takes the page's width up to its display_width: its own pixel width, or FIGURE_MIN_PX
# when smaller (the page copies are 825 to 1100 px wide, EMBED_MAX_WIDTH at most), upscaled by
# MAX_UPSCALE at most. One figure a row: at 1400 px every figure takes 75% of the content or more.
FIGURE_MIN_PX = 1000
MAX_UPSCALE = 1.25


class Html(str):
    """Text that is already HTML (a link in a table cell): not escaped again."""


def esc(value) -> str:
    return value if isinstance(value, Html) else html.escape(str(value), quote=True)


def relative_href(path: Path, out_dir: Path) -> str:
    """A link to ``path`` from a page in ``out_dir``: it works wherever the results folder is moved."""
    return Path(os.path.relpath(path, out_dir)).as_posix()


def link(href: str, text: str) -> Html:
    return Html(f'<a href="{esc(href)}">{esc(text)}</a>')


def page(title: str, body: list[str]) -> str:
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{esc(title)}</title><style>{STYLE}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n"
    )


def data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def png_size(png: bytes) -> tuple[int, int]:
    """A PNG's width and height in pixels, from its header."""
    return struct.unpack(">II", png[16:24])


def display_width(pixels: int) -> int:
    """The widest a figure of ``pixels`` width is shown, in CSS px (the page narrower: the page's
    width): its own width, brought up to FIGURE_MIN_PX but never more than MAX_UPSCALE times it."""
    return min(max(pixels, FIGURE_MIN_PX), round(pixels * MAX_UPSCALE))


def hover_spans(spots) -> str:
    """Spans laid over a figure's image, one per hover spot (``plots.study.HoverSpot``): the
    pointer on one shows its numbers (its title). In % of the image, so they scale with it."""
    spans = []
    for spot in spots:
        left, top, right, bottom = (100 * v for v in spot.box)
        spans.append(
            f'<span style="left:{left:.2f}%;top:{top:.2f}%;width:{right - left:.2f}%;height:{bottom - top:.2f}%" '
            f'title="{esc(spot.text)}"></span>'
        )
    return "".join(spans)


def embedded_image(compact: bytes, caption: str, spots=()) -> str:
    """A figure element holding an already compacted PNG (see ``plots.png.compact_image``): as wide
    as the page up to its ``display_width``; its size in the img tag gives its box before it
    decodes. ``spots``: the figure's hover spots, laid over the image."""
    width, height = png_size(compact)
    img = f'<img src="{data_uri(compact)}" alt="{esc(caption)}" width="{width}" height="{height}">'
    if spots:
        img = f'<div class="hover-spots">{img}{hover_spans(spots)}</div>'
    return f'<figure style="max-width:{display_width(width)}px">{img}<figcaption>{esc(caption)}</figcaption></figure>'


def image(png: bytes, caption: str, spots=()) -> str:
    return embedded_image(compact_png(png), caption, spots)


def linked_image(href: str, caption: str) -> str:
    """A figure element that links its PNG file (relative to the page) instead of embedding it."""
    return (
        f'<figure class="linked"><figcaption>{esc(caption)}</figcaption><a href="{esc(href)}">open figure</a></figure>'
    )


def missing_image(caption: str, path: Path) -> str:
    """The visible note in place of a figure that was not drawn."""
    return f'<p class="missing">{esc(caption)}: not drawn ({esc(path.name)} missing)</p>'


def image_file(path: Path, caption: str, spots=()) -> str:
    """An embedded PNG file (its page copy), or a visible note when the figure was not drawn."""
    if not path.is_file():
        return missing_image(caption, path)
    return embedded_image(compact_file(path), caption, spots)


def format_cell(value) -> str:
    if isinstance(value, float):
        if math.isnan(value):
            return ""
        return f"{value:.4g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(format_cell(float(v)) if isinstance(v, (int, float)) else esc(v) for v in value) + "]"
    return esc(value)


def header(text: str) -> str:
    """A column header, escaped, that wraps at its spaces except around a slash ("removed 1 / 2"),
    and may break after the underscores of a column name ("p95_magnitude")."""
    return esc(text).replace(" / ", "\u00a0/\u00a0").replace("_", "_<wbr>")


def table(
    headers: list[str],
    rows: list[list],
    row_classes: list[str] | None = None,
    text_columns: int = 0,
    cell_classes: list[list[str]] | None = None,
    prose_columns: tuple[int, ...] = (),
) -> str:
    """An HTML table in its own box, which scrolls sideways when the table is wider than the page
    (and down, its header kept in view, when it is taller than the window). Headers wrap; the
    first ``text_columns`` columns are left-aligned text, the ``prose_columns`` (indices) too,
    and these wrap at their spaces when the table would be wider than the page."""

    def kind(i: int) -> str:
        return "text prose" if i in prose_columns else "text" if i < text_columns else ""

    head = "".join(
        f'<th class="{kind(i)}">{header(h)}</th>' if kind(i) else f"<th>{header(h)}</th>" for i, h in enumerate(headers)
    )
    body = []
    for r, row in enumerate(rows):
        row_cls = f' class="{row_classes[r]}"' if row_classes and row_classes[r] else ""
        cells = []
        for i, v in enumerate(row):
            extra = cell_classes[r][i] if cell_classes else ""
            klass = " ".join(c for c in (kind(i), extra) if c)
            cells.append(f'<td class="{klass}">{format_cell(v)}</td>' if klass else f"<td>{format_cell(v)}</td>")
        body.append(f"<tr{row_cls}>" + "".join(cells) + "</tr>")
    return (
        f'<div class="table-box"><table><thead><tr>{head}</tr></thead><tbody>'
        + "".join(body)
        + "</tbody></table></div>"
    )
