"""Offline analyses that reproduce the thesis' tables (run as python -m cdpr_control.analysis.<name>)."""
