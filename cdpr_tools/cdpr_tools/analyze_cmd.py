"""``cdpr analyze``: offline analyses of the thesis.

    force-distribution   tables 3.2/3.3 (cdpr_control.analysis.force_distribution_comparison)
    energy               energy model (4.9)-(4.14) of a bag or a planned trajectory (section 4.4)
    eigenfrequencies     stiffness and eigenfrequency maps over the workspace (section 4.3)
    stability            gain and phase margins of CFC and OSPC (sections 3.1.3, 3.4)
"""
from __future__ import annotations

import importlib

# analysis name -> module with main(argv)
ANALYSES = {
    "force-distribution": "cdpr_control.analysis.force_distribution_comparison",
    "energy": "cdpr_tools.analyze_energy",
    "eigenfrequencies": "cdpr_control.analysis.eigenfrequencies",
    "stability": "cdpr_control.analysis.stability",
}
WITH_PROGRESS = {"force-distribution"}  # main(argv, progress=...): tells how far the work is


def add_parser(sub) -> None:
    p = sub.add_parser("analyze", help="offline analyses (force-distribution, energy, eigenfrequencies, stability)")
    p.add_argument("analysis", choices=tuple(ANALYSES), help="what to analyse")
    p.add_argument("options", nargs="...", help="options of the analysis (--help after the name lists them)")
    p.set_defaults(run=run)


def run(args) -> int:
    main = importlib.import_module(ANALYSES[args.analysis]).main
    if args.analysis not in WITH_PROGRESS:
        return main(args.options)
    from cdpr_tools.progress import Progress

    progress = Progress(f"analyze {args.analysis}")
    try:
        code = main(args.options, progress=progress.update)
    except BaseException:
        progress.stop()                 # no "100 %" after an error: the error is the last line
        raise
    progress.done()
    return code
