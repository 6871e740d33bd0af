"""The project's one way to compile: :func:`njit` = ``numba.njit`` cached on disk, the cache kept per
version of the compiled sources.

numba's disk cache (``cache=True``) checks only the modification time of the file that defines a
function, not of the files its callees come from: after an edit of a callee in another file
(``kernels.model.cholesky_solve`` called by the simulator's cable wrench, the simulator's period
calling five modules) a cached caller would keep the old callee. So the cache lives in a
directory named for a hash of every compiled source of the project (:data:`COMPILED_SOURCES`, checked
by tests/architecture/test_layout.py): an edit of any of them compiles afresh, the older directories
are removed but the newest few (switching branches back and forth does not recompile everything).
The base directory is ``NUMBA_CACHE_DIR`` when set, else ``$XDG_CACHE_HOME/cdpr/numba``
(``~/.cache/cdpr/numba``); if it cannot be written, numba's own default (``__pycache__``) is used.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import shutil
from pathlib import Path

import numba

# package -> its modules (paths inside the package) that define or compile numba functions
COMPILED_SOURCES = {
    "cdpr_control": ["kernels/control.py", "kernels/friction.py", "kernels/model.py", "kernels/robot_data.py",
                     "kernels/setpoint.py", "kernels/jit.py", "model/friction.py"],
    "cdpr_sim": ["cables.py", "drive_models.py", "period.py", "plant.py", "sensors.py"],
}
KEEP = 4                      # cache directories of other source versions kept (newest first)
_configured: str | None = None


def sources_digest() -> str:
    """A hash of every compiled source of the project that is installed (cdpr_sim may be absent)."""
    h = hashlib.sha256()
    for package, files in COMPILED_SOURCES.items():
        spec = importlib.util.find_spec(package)
        if spec is None or not spec.submodule_search_locations:
            continue
        root = Path(next(iter(spec.submodule_search_locations)))
        for name in files:
            path = root / name
            h.update(f"{package}/{name}\0".encode())
            h.update(path.read_bytes() if path.exists() else b"")
    return h.hexdigest()[:16]


def _base() -> Path:
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "cdpr" / "numba"


def configure() -> str | None:
    """Point numba's cache at this source version's directory (once per process); its path, or None
    when it cannot be written (numba's default then)."""
    global _configured
    if _configured is None:
        base = _base()
        directory = base / sources_digest()
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError:
            _configured = ""
            return None
        others = sorted((d for d in base.iterdir() if d.is_dir() and d != directory),
                        key=lambda d: d.stat().st_mtime, reverse=True)
        for old in others[KEEP:]:
            shutil.rmtree(old, ignore_errors=True)
        os.utime(directory)                                   # the newest in use
        numba.config.CACHE_DIR = str(directory)
        _configured = str(directory)
    return _configured or None


def njit(fn=None, **options):
    """``numba.njit(fn, cache=True, **options)`` with the cache of :func:`configure`; as a decorator
    with or without options (``@njit``, ``@njit(error_model="numpy")``)."""
    configure()
    options.setdefault("cache", True)
    if fn is None:
        return numba.njit(**options)
    return numba.njit(**options)(fn)
