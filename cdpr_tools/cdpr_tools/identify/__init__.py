"""Parameter identification from recorded bags (``cdpr identify``), thesis sections 3.3.1 and 3.7.2.

One module per identification, each reading only a bag as a real robot records it:
:mod:`.friction` (pulley friction (3.45)), :mod:`.drive` (PT1 + dead time (3.10) or second
order (5.11)); :mod:`.experiments` records the identification runs with the simulator;
:mod:`.bag_data` turns the bag's topics into aligned numpy series.
"""
