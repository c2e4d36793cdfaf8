"""Writing a figure: its PNG (and SVG when asked and small), with the page copy, atomically;
or its PNG bytes for a page."""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib.pyplot as plt

from ..io.atomic import atomic_path
from .png import compact_image, encode_png, figure_image, figure_png, page_copy_path
from .settings import PlotSettings

SVG_MAX_BYTES = 2_000_000  # "SVG where it stays small": above this only the PNG is kept


def save(fig, out_dir: Path, stem: str, settings: PlotSettings) -> list[Path]:
    """Write ``stem.png`` (and ``stem.svg`` when asked and small enough) atomically; close.
    Beside the PNG, its page copy (``plots.png.compact_file``) from the same image."""
    written = []
    try:
        for fmt in settings.formats:
            if fmt == "png":
                image = figure_image(fig, settings.dpi)
                data = encode_png(image, settings.dpi)
            else:
                buf = io.BytesIO()
                fig.savefig(buf, format=fmt, dpi=settings.dpi)
                data = buf.getvalue()
                if len(data) > SVG_MAX_BYTES:
                    continue
            path = out_dir / f"{stem}.{fmt}"
            with atomic_path(path) as tmp:
                tmp.write_bytes(data)
            written.append(path)
            if fmt == "png":  # after the file: a copy older than its file is not used
                with atomic_path(page_copy_path(path)) as tmp:
                    tmp.write_bytes(compact_image(image))
    finally:
        plt.close(fig)
    return written


def png_bytes(fig, dpi: int) -> bytes:
    """The figure as PNG bytes (for embedding in a report); closes the figure."""
    try:
        return figure_png(fig, dpi)
    finally:
        plt.close(fig)
