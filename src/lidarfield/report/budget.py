"""Keeping the study report under a size budget, so that it can still be mailed.

Figures are embedded a whole tier at a time (so every pair's section shows the same figures),
tier after tier while the page fits; from the first tier that does not fit, every figure is a
link to its PNG file instead. Sizes are exact UTF-8 byte counts: the page with every figure
linked is measured once, and embedding a figure adds the difference between its two elements.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from ..defaults import default
from ..io.atomic import write_text
from ..plots.png import compact_file
from .page import embedded_image, esc, linked_image, missing_image, page, relative_href

log = logging.getLogger(__name__)

MB = 1_000_000  # the budget's unit: mail size limits are quoted in decimal megabytes


@dataclass(frozen=True, eq=False)  # eq=False: hashed by identity, a key of the embedded mapping
class Figure:
    """A figure of the page that its tier's fit decides to embed or to link."""

    tier: str  # the tier's name, as the page's note says it
    caption: str
    href: str | None  # its PNG file relative to the page; None when it was drawn for the page only
    compact: Callable[[], bytes]  # its page copy, read (or drawn) only when its tier is tried

    def embedded(self, compact: bytes) -> str:
        return embedded_image(compact, self.caption)

    def linked(self) -> str:
        if self.href is None:
            return f'<p class="missing">{esc(self.caption)}: not embedded (size budget) and not on disk to link</p>'
        return linked_image(self.href, self.caption)


def file_figure(tier: str, path: Path, caption: str, out_dir: Path) -> Figure | str:
    """A figure drawn to a PNG file, or the note that it was not drawn."""
    if not path.is_file():
        return missing_image(caption, path)
    return Figure(tier, caption, relative_href(path, out_dir), partial(compact_file, path))


class Note:
    """Where the page says what the budget left out (a placeholder among the page's parts)."""


def utf8_len(text: str) -> int:
    return len(text.encode("utf-8"))


def default_max_mb() -> float:
    """The config schema's default of ``report.max_mb`` (the schema is the one place it is set)."""
    return default("report", "max_mb")


def budget_mb(study: dict | None, max_mb: float | None) -> float:
    """``max_mb`` when given, else the study's ``report.max_mb``, else the schema's default."""
    if max_mb is not None:
        return max_mb
    return ((study or {}).get("report") or {}).get("max_mb", default_max_mb())


def render(parts: list, embedded: dict[Figure, bytes], note: str) -> list[str]:
    """The page's HTML parts: each figure embedded or linked, the note in its place."""

    def html(part) -> str:
        if isinstance(part, Note):
            return note
        if isinstance(part, Figure):
            return part.embedded(embedded[part]) if part in embedded else part.linked()
        return part

    return [html(p) for p in parts]


def _compact_tier(tier: list[Figure], room_bytes: int) -> tuple[dict[Figure, bytes], int] | None:
    """The tier's compacted PNGs and how much they grow the page; None as soon as they outgrow
    ``room_bytes``, without reading (or drawing) the rest."""
    compacted, growth = {}, 0
    for figure in tier:
        compacted[figure] = figure.compact()
        growth += utf8_len(figure.embedded(compacted[figure])) - utf8_len(figure.linked())
        if growth > room_bytes:
            return None
    return compacted, growth


def embed_tiers(
    tiers: list[list[Figure]], linked_page_bytes: int, budget_bytes: int, note: Callable[[Collection[Figure]], str]
) -> dict[Figure, bytes]:
    """The compacted PNG of every figure to embed: whole tiers, in order, up to the first one
    that would take the page over ``budget_bytes``.

    ``linked_page_bytes`` is the size of the page with every figure linked and an empty note;
    ``note(embedded)`` is the note the page carries when those figures are embedded.
    """
    embedded: dict[Figure, bytes] = {}
    page_bytes = linked_page_bytes
    for tier in tiers:
        # The note only grows the page: a tier that overflows without it cannot fit.
        fit = _compact_tier(tier, budget_bytes - page_bytes)
        if fit is None:
            break
        candidate = embedded | fit[0]
        if page_bytes + fit[1] + utf8_len(note(candidate)) > budget_bytes:
            break
        embedded, page_bytes = candidate, page_bytes + fit[1]
    return embedded


def budget_note(figures: list[Figure], embedded: Collection[Figure], max_mb: float) -> str:
    """What the budget left out, in plain words ('' when every figure is embedded)."""
    linked = [f for f in figures if f not in embedded]
    if not linked:
        return ""

    def tiers(group: list[Figure]) -> str:
        return ", ".join(dict.fromkeys(f.tier for f in group)) or "none"

    kept = [f for f in figures if f in embedded]
    return (
        f'<p class="budget">This page has a size budget of {max_mb:g} MB, so that it can be mailed: '
        f"{len(kept)} of its {len(figures)} pair and stage figures are embedded (tiers: {esc(tiers(kept))}) "
        f"and the other {len(linked)} are linked (tiers: {esc(tiers(linked))}). An “open figure” link opens "
        "the PNG file when this page is opened inside its results folder. A larger <code>report.max_mb</code> "
        "in the config (or <code>lidarfield report --max-mb</code>) embeds more.</p>"
    )


def write_within_budget(parts: list, tiers: tuple[str, ...], title: str, out_html: Path, max_mb: float) -> Path:
    """Write the page of ``parts``, its figures embedded tier by tier (in the order of ``tiers``)
    while it stays within ``max_mb``, the others linked; log its size and both counts."""
    figures = [p for p in parts if isinstance(p, Figure)]
    by_tier = [[f for f in figures if f.tier == tier] for tier in tiers]
    note = partial(budget_note, figures, max_mb=max_mb)
    budget_bytes = int(max_mb * MB)
    embedded = embed_tiers(by_tier, utf8_len(page(title, render(parts, {}, ""))), budget_bytes, note)
    html = page(title, render(parts, embedded, note(embedded)))
    write_text(out_html, html)
    size = utf8_len(html)
    log.info(
        "%s: %.2f MB (budget %g MB), %d figures embedded, %d linked",
        out_html,
        size / MB,
        max_mb,
        len(embedded),
        len(figures) - len(embedded),
    )
    if size > budget_bytes:
        log.warning("%s is over its %g MB budget even with every pair and stage figure linked", out_html, max_mb)
    return out_html
