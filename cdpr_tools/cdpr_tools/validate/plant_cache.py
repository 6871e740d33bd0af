"""What the sweep identifies on a case's plant before running it (the friction of the guiding cases,
:mod:`.friction`; the cable settlement of the payload cases, :mod:`.settlement`), as a user would on
the robot: one parameter file per (robot, plant, seed) in the output directory, identified once and
reused by every later run with that directory, also by concurrent sweeps or processes of one."""
from __future__ import annotations

import shutil
from pathlib import Path
from typing import Callable

from cdpr_tools.file_lock import locked


def parameter_path(outdir, kind: str, robot_name: str, plant: str, seed: int) -> Path:
    """``<outdir>/<kind>/<robot>_<plant>[_seed<N>].yaml``: where the sweep keeps what it identified."""
    name = f"{robot_name}_{plant}" + (f"_seed{seed}" if plant != "nominal" else "")
    return Path(outdir) / kind / f"{name}.yaml"


def identified_once(path: Path, identify: Callable[[Path], None]) -> bool:
    """``identify(path)`` unless ``path`` exists, under a file lock beside it; True: it existed (reused)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with locked(path.with_suffix(".lock")):
        reused = path.is_file()
        if not reused:
            identify(path)
    return reused


def run_directory(path: Path) -> Path:
    """Where the identification run of ``path`` records its bag (``<stem>_run/``), emptied of what a
    run cut off before its fit was written left there."""
    bag_dir = path.parent / f"{path.stem}_run"
    if bag_dir.exists():
        shutil.rmtree(bag_dir)
    return bag_dir
