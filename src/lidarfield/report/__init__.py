"""The study report (``write_report``), the comparison of two studies (``compare_studies``),
and the discovery of pairs and stages in a results folder (``discover``)."""

from __future__ import annotations

from .compare import compare_studies
from .discover import discover, read_summary
from .html import write_report

__all__ = ["compare_studies", "discover", "read_summary", "write_report"]
