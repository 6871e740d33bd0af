"""``cdpr analyze force-distribution``: the comparison of thesis tables 3.2 and 3.3."""
from __future__ import annotations


def add_parser(sub) -> None:
    p = sub.add_parser("analyze", help="offline analyses (force-distribution: thesis tables 3.2/3.3)")
    p.add_argument("analysis", choices=("force-distribution",), help="what to analyse")
    p.add_argument("options", nargs="...", help="options of the analysis (--help after the name lists them)")
    p.set_defaults(run=run)


def run(args) -> int:
    from cdpr_control.analysis.force_distribution_comparison import main
    from cdpr_tools.progress import Progress

    progress = Progress("analyze force-distribution")
    try:
        return main(args.options, progress=progress.update)
    finally:
        progress.done()
