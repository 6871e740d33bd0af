"""The control stages of Fig. 3.4 and chapter 5, one module per box, and ControlLoop (loop.py), which runs them in one process."""
