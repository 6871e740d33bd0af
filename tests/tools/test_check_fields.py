"""The suite runs with ROS_PYTHON_CHECK_FIELDS=1 (tests/conftest.py, issue 28): a wrong field type
fails a test with a Python error, here and in every `cdpr` subprocess a test starts, instead of
asserting in the C conversion and aborting the process (`cdpr program run FILE.gcode` sent the
file's Path as the goal's name and died with exit 134)."""
import os
import subprocess
import sys
from pathlib import Path

import pytest
from cdpr_msgs.action import RunProgram

from cdpr_test_nodes.graph import subprocess_env


def test_a_wrong_field_type_is_a_python_error_in_the_suite():
    assert os.environ.get("ROS_PYTHON_CHECK_FIELDS") == "1"
    with pytest.raises(AssertionError, match="'name' field must be of type 'str'"):
        RunProgram.Goal(program="G90\n", name=Path("my.gcode"))


def test_and_in_the_subprocesses_it_starts():
    code = ("from pathlib import Path\nfrom cdpr_msgs.action import RunProgram\n"
            "RunProgram.Goal(program='G90', name=Path('my.gcode'))\n")
    run = subprocess.run([sys.executable, "-c", code], env=subprocess_env(), capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 1 and "AssertionError" in run.stderr, run.stderr
