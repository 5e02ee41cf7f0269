"""``onionsort report``: a run folder's settings and results as ``RUN_DIR/report.md``.

Works out from its files whether RUN_DIR is a demo, an experiment, a learning run or an
evaluation, and writes one Markdown page of its settings and results beside them: for a demo,
Table 1 (per method, pooled over the repeats with 95% intervals, and per repeat), the
calibrated error rates and the deferring sort where there is one; for an experiment, the
summary table and its plots; for a learning run, the reward, policy, learning curve and policy
confidence; for an evaluation, the counts, precision, recall and deferral. It draws
``report_pr.png`` (precision and recall per method), links the run's own figures, and lists
its ``.rrd`` and ``.mcap`` files with the command that opens each. It reads the files only,
and replaces an earlier ``report.md``. ``onionsort demo`` and ``onionsort experiment`` write
one at the end.

Examples
--------
    onionsort report runs/demo-quick
    onionsort report runs/experiment-forestworld
    onionsort report runs/learn-mmap
"""

from __future__ import annotations

from onionsort.commands import add_command
from onionsort.configs import config_from_args
from onionsort.configs.report import ReportConfig


def register(subparsers) -> None:
    add_command(subparsers, "report", __doc__,
                "write a run folder's settings and results as RUN_DIR/report.md", ReportConfig, run)


def run(args) -> int:
    from onionsort.stages.report import report, run_kind

    path = report(config_from_args(ReportConfig, args))
    print(f"wrote {path} ({run_kind(args.run)} run)")
    return 0
