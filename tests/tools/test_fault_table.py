"""docs/faults.md (made by `make fault-table`) lists every fault test of the suite: a fault test
added, renamed or re-described without regenerating the table fails here."""
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def fault_table():
    spec = importlib.util.spec_from_file_location("fault_table", ROOT / "scripts" / "fault_table.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_fault_test_has_its_row_in_docs_faults_md():
    ft = fault_table()
    table = (ROOT / "docs" / "faults.md").read_text()
    missing = [f"{file}: {text}" for file in ft.FAULT_TESTS for text in ft.descriptions(ROOT / file).values()
               if f"| {text} |" not in table]
    assert not missing, "docs/faults.md is stale (run `make fault-table`): " + "; ".join(missing)


def test_the_table_counts_tries_held_and_lost_from_junit(tmp_path):
    junit = tmp_path / "r.xml"
    junit.write_text(
        '<testsuites><testsuite>'
        '<testcase classname="tests.faults.test_x" name="test_a[1]"/>'
        '<testcase classname="tests.faults.test_x" name="test_a[2]"><failure message="x"/></testcase>'
        '<testcase classname="tests.faults.test_x" name="test_b"><skipped/></testcase>'
        '<testcase classname="tests.faults.test_x" name="test_c"><skipped type="pytest.xfail" message="open"/></testcase>'
        '</testsuite></testsuites>')
    counts = fault_table().outcomes(junit)
    a, b = counts[("tests/faults/test_x.py", "test_a")], counts[("tests/faults/test_x.py", "test_b")]
    assert (a["tries"], a["held"], a["lost"]) == (2, 1, 1) and (b["tries"], b["skipped"], b["held"]) == (1, 1, 0)
    c = counts[("tests/faults/test_x.py", "test_c")]        # a known open fault (strict xfail) is lost
    assert (c["tries"], c["lost"], c["skipped"], c["held"]) == (1, 1, 0, 0)
