"""The validation sweep of ``cdpr validate`` (issue 25): contact, hand guiding, payloads and a
program, run in process at poses spread over each robot's wrench-feasible workspace, measured
against the thesis' bands.

* :mod:`.grid`: the poses (a third of them near the workspace's border);
* :mod:`.cases`: one runner per case family, against the simulator;
* :mod:`.criteria`: the metrics and the bands;
* :mod:`.report`: JSON, the one-line summaries and a figure per family.
"""
