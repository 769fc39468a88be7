"""``corl report``: one self-contained HTML page per stored run.

:mod:`~corl.experiments.html.report` gathers what a page shows (the replayed learner, J of every
trial, figures and the video as ``data:`` URIs); :mod:`~corl.experiments.html.page` writes the
markup.
"""

from corl.experiments.html.report import VIDEO_NAMES, RunReport, collect_report, data_uri, write_reports

__all__ = ["RunReport", "collect_report", "write_reports", "data_uri", "VIDEO_NAMES"]
