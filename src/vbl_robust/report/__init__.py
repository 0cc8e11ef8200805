"""Figures (matplotlib, Agg) and the self-contained HTML report of a campaign's results store.

>>> from vbl_robust.report import build_report  # build_report("runs/demo") -> runs/demo/report.html
"""

from .build import build_report

__all__ = ["build_report"]
