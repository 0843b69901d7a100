"""One self-contained HTML page of one run or of several side by side (`neoslam report`): the figures of each
results folder embedded, the metrics table, the time by stage and the configuration that differed."""

from neoslam.report.page import render_report
from neoslam.report.results import RunFolder, read_results

__all__ = ["RunFolder", "read_results", "render_report"]
