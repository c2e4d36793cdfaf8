"""The study report (``write_report``: the overview and one page per pair; ``write_overview``
and ``write_pair_page`` as the workflow's jobs call them), the comparison of two studies
(``compare_studies``), and the discovery of pairs and stages in a results folder (``discover``)."""

from __future__ import annotations

from .compare import compare_studies
from .discover import discover, read_summary
from .html import write_report
from .overview import write_overview
from .pair_page import write_pair_page

__all__ = ["compare_studies", "discover", "read_summary", "write_overview", "write_pair_page", "write_report"]
