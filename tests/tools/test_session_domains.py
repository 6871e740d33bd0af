"""Test sessions on one machine get ROS domains of their own (tests/conftest.py: claim_domain)."""
import subprocess
import sys
from pathlib import Path

from conftest import claim_domain

HOLD = """
import sys, time
sys.path.insert(0, {tests!r})
from conftest import claim_domain
domain, lock = claim_domain({first})
print(domain, flush=True)
time.sleep(60)
"""


def test_a_domain_another_session_holds_is_skipped_and_freed_when_it_ends():
    tests = str(Path(__file__).parents[1])
    mine, lock = claim_domain(1)
    lock.close()                                # free again: the other session may take it
    other = subprocess.Popen([sys.executable, "-c", HOLD.format(tests=tests, first=mine)],
                             stdout=subprocess.PIPE, text=True)
    try:
        held = int(other.stdout.readline())
        domain, lock = claim_domain(held)
        assert domain != held                   # held by the other session: the next free one
        lock.close()
    finally:
        other.kill()
        other.wait()
    domain, lock = claim_domain(held)           # its lock went with the process
    lock.close()
    assert domain == held
