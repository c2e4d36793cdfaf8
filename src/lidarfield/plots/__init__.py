"""Figures of a stage and of a pair (matplotlib, Agg) and the interactive 3-D view (plotly).

``plot_stage`` writes the figures of one stage folder (:mod:`.stage`), ``plot_pair`` those of
a pair's summary rows (:mod:`.pair_stats`). Names are imported on first use, so that the
settings (:mod:`.settings`, read when a config is validated) come without matplotlib.
"""

from __future__ import annotations

import importlib

# public name -> module that defines it
_EXPORTS = {
    "STAGE_FIGURES": "settings",
    "PlotSettings": "settings",
    "plot_settings": "settings",
    "plot_stage": "stage",
    "stage_figures": "stage",
    "plot_pair": "pair_stats",
    "write_plotly_js": "interactive",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'lidarfield.plots' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
