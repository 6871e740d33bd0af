"""One way to compile and one place to choose (issue 24, item 3): every numba function of the
project is compiled with kernels.jit.njit from a file listed in COMPILED_SOURCES (the key of its
disk cache), and no module but kernels/__init__.py branches on kernels.ENABLED (the laws do)."""
import ast
from pathlib import Path

from cdpr_control.kernels.jit import COMPILED_SOURCES

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = {"cdpr_control": ROOT / "cdpr_control" / "cdpr_control", "cdpr_sim": ROOT / "cdpr_sim" / "cdpr_sim"}


def modules():
    for package, root in PACKAGES.items():
        for path in sorted(root.rglob("*.py")):
            yield package, path.relative_to(root).as_posix(), ast.parse(path.read_text())


def _is_numba_jit(node) -> bool:
    return isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "numba" \
        and node.attr in ("njit", "jit")


def _reads_enabled(node) -> bool:
    return any(isinstance(n, ast.Attribute) and n.attr == "ENABLED" and isinstance(n.value, ast.Name)
               and n.value.id == "kernels" for n in ast.walk(node))


def test_every_compiled_function_is_compiled_by_the_project_njit_in_a_listed_file():
    raw, unlisted = [], []
    for package, name, tree in modules():
        if name == "kernels/jit.py":
            continue
        if any(_is_numba_jit(n) for n in ast.walk(tree)):
            raw.append(f"{package}/{name}")
        uses_njit = any(isinstance(n, ast.ImportFrom) and n.module == "cdpr_control.kernels.jit" for n in ast.walk(tree))
        if uses_njit and name not in COMPILED_SOURCES[package]:
            unlisted.append(f"{package}/{name}")
    assert not raw, f"numba.njit used directly (use cdpr_control.kernels.jit.njit): {raw}"
    assert not unlisted, f"compiled sources missing from kernels.jit.COMPILED_SOURCES: {unlisted}"


def test_only_the_laws_choose_between_reference_and_compiled_code():
    branching = []
    for package, name, tree in modules():
        if name == "kernels/__init__.py":
            continue
        for n in ast.walk(tree):
            if isinstance(n, (ast.If, ast.IfExp, ast.While)) and _reads_enabled(n.test):
                branching.append(f"{package}/{name}:{n.lineno}")
    assert not branching, f"branches on kernels.ENABLED outside kernels (make it a kernels.law): {branching}"


def test_a_changed_compiled_source_gets_a_cache_directory_of_its_own(tmp_path, monkeypatch):
    from cdpr_control.kernels import jit
    before = jit.sources_digest()
    fake = tmp_path / "cdpr_control"
    for name in COMPILED_SOURCES["cdpr_control"]:
        (fake / name).parent.mkdir(parents=True, exist_ok=True)
        (fake / name).write_bytes((PACKAGES["cdpr_control"] / name).read_bytes())
    (fake / "__init__.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    import importlib
    import sys
    monkeypatch.delitem(sys.modules, "cdpr_control", raising=False)
    importlib.invalidate_caches()
    assert jit.sources_digest() == before                                   # the same sources: the same key
    (fake / "kernels" / "model.py").write_text((fake / "kernels" / "model.py").read_text() + "\n# an edit\n")
    assert jit.sources_digest() != before                                   # a callee's file edited: a new key
