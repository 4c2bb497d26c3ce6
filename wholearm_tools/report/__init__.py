"""Accuracy against ground truth, the well-junction summary and the PDF report.

:func:`evaluate` (``metrics``) and :func:`junction_summary` (``junction``) are pure numpy;
:func:`write_report` (``pdf``) imports matplotlib and pyvista only when called; what a report
shows is one :class:`ReportData` (``data``), read from an output folder with
:func:`load_report_data`.
"""

from wholearm_tools.report.data import ReportData, load_report_data
from wholearm_tools.report.junction import Estimate, JunctionSummary, junction_summary
from wholearm_tools.report.metrics import (
    AccuracyReport,
    ClassificationMetrics,
    PrimitiveAccuracy,
    SurfaceRecovery,
    classification_metrics,
    evaluate,
)
from wholearm_tools.report.pdf import ReportInfo, write_report

__all__ = ["AccuracyReport", "ClassificationMetrics", "Estimate", "JunctionSummary",
           "PrimitiveAccuracy", "ReportData", "ReportInfo", "SurfaceRecovery",
           "classification_metrics", "evaluate", "junction_summary", "load_report_data",
           "write_report"]
