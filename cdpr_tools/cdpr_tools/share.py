"""Where a package's share files (params, robots, programs, graphs) are: ``$(find-pkg-share PKG)``.

A colcon build or a ROS 2 install puts them under ``<prefix>/share/<pkg>`` and registers the
package in the ament resource index (``AMENT_PREFIX_PATH``); :func:`package_share` asks
``ament_index_python`` first. In a source checkout installed with ``pip install -e`` there is no
index entry and no copy (the setup files leave the copy out, so edits never go stale): the share
is the Python package's own directory, which holds the same sub-folders (``params/``, ``robots/``,
``programs/``, ``graphs/``) as the installed share.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory


def package_share(package: str) -> Path:
    """The share directory of ``package`` (ament index first, then the importable source package)."""
    try:
        return Path(get_package_share_directory(package))
    except (PackageNotFoundError, EnvironmentError):  # not in the index, or AMENT_PREFIX_PATH unset
        pass
    except ValueError as exc:  # an invalid package name
        raise LookupError(str(exc)) from None
    spec = importlib.util.find_spec(package) if package.isidentifier() else None
    if spec is None or not spec.submodule_search_locations:
        raise LookupError(f"package {package!r} is neither in the ament index (AMENT_PREFIX_PATH) "
                          "nor an importable Python package")
    return Path(next(iter(spec.submodule_search_locations)))
