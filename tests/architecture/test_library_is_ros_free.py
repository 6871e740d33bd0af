"""The library parts of cdpr_control and cdpr_sim import no rclpy (the node layer lives in .ros, nodes in .nodes)."""
import subprocess
import sys

CHECK = r"""
import importlib, pkgutil, sys
import cdpr_control, cdpr_sim
assert 'rclpy' not in sys.modules, 'import cdpr_control pulled in rclpy'
for pkg in (cdpr_control, cdpr_sim):
    for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):
        if '.nodes' in info.name or '.ros' in info.name:
            continue
        importlib.import_module(info.name)
        assert 'rclpy' not in sys.modules, f'{info.name} imports rclpy'
print('ok')
"""


def test_library_modules_do_not_import_rclpy():
    out = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
