"""Sample G-code programs shipped as package data (dialect: docs/gcode.md)."""
from importlib import resources
from pathlib import Path

from cdpr_control.motion.gcode import program_text


def names() -> list[str]:
    """File names of the sample programs, e.g. 'rectangle.gcode'."""
    return sorted(p.name for p in resources.files(__name__).iterdir() if p.name.endswith(".gcode"))


def read(name: str) -> str:
    """Text of the sample program `name` (with or without the .gcode suffix)."""
    if not name.endswith(".gcode"):
        name += ".gcode"
    return resources.files(__name__).joinpath(name).read_text(encoding="utf-8")


def source(program: str) -> tuple[str, str]:
    """(name, text) of ``program``: a G-code file or the name of a sample program. Errors name the
    file: a directory or a fifo is refused, bytes that are not UTF-8 raise GCodeError with the
    line:col of the first one (motion.gcode.program_text)."""
    path = Path(program)
    if path.is_dir():
        raise IsADirectoryError(f"{program}: is a directory, not a G-code file")
    if path.exists() and not path.is_file():     # a fifo or a device would block or never end
        raise OSError(f"{program}: is not a regular file, not a G-code file")
    if path.exists():
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise OSError(f"{program}: cannot read: {exc.strerror}") from None
        return path.stem, program_text(data)
    if program in names() or f"{program}.gcode" in names():
        return program.removesuffix(".gcode"), read(program)
    raise FileNotFoundError(f"no file {program!r} and no shipped program of that name; shipped: {', '.join(names())}")
