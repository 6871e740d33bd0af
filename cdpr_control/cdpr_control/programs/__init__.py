"""Sample G-code programs shipped as package data (dialect: docs/gcode.md)."""
from importlib import resources


def names() -> list[str]:
    """File names of the sample programs, e.g. 'rectangle.gcode'."""
    return sorted(p.name for p in resources.files(__name__).iterdir() if p.name.endswith(".gcode"))


def read(name: str) -> str:
    """Text of the sample program `name` (with or without the .gcode suffix)."""
    if not name.endswith(".gcode"):
        name += ".gcode"
    return resources.files(__name__).joinpath(name).read_text(encoding="utf-8")
