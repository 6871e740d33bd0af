"""The library's layout is Fig. 3.4's: folders by stage, imports only downward, no cycles, no private names.

An import walk over the sources (ast, nothing imported): every module of ``cdpr_control`` lives in one
of the folders below; ``nodes/`` holds node modules only; a module imports only from its own folder or
from folders below it in LAYERS (function-level imports included: a lazy import is still a
dependency); the module-level import graph of the three packages has no cycle; no module imports a
private (``_``-prefixed) name of a module in another folder; cdpr_control imports neither cdpr_sim nor
cdpr_tools, cdpr_sim not cdpr_tools.
"""
from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("cdpr_control", "cdpr_sim", "cdpr_tools")
# cdpr_control's folders, lowest first: a folder imports only from its own rank and below. The
# force distribution is pure linear algebra on A^T and w; model holds the robot (and the compiled
# twins' numeric cores in kernels share its rank: the references and the twins are tested against
# each other); motion plans paths on the model; control holds the stages; analysis studies them;
# ros is the node layer and nodes the nodes.
LAYERS = {"force_distribution": 0, "model": 1, "kernels": 1, "motion": 2, "control": 3, "analysis": 4,
          "programs": 4, "ros": 5, "nodes": 6}
PACKAGE_RANK = {"cdpr_control": 0, "cdpr_sim": 1, "cdpr_tools": 2}


def _modules():
    """{module name: (path, ast tree)} of the three packages' sources."""
    out = {}
    for pkg in PACKAGES:
        base = ROOT / pkg
        for path in sorted((base / pkg).rglob("*.py")):
            parts = list(path.relative_to(base).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = (path, ast.parse(path.read_text(encoding="utf-8")))
    return out


MODULES = _modules()


def _imports(tree, top_level_only=False):
    """(module, [names]) of every absolute import of the project in a tree."""
    nodes = tree.body if top_level_only else ast.walk(tree)
    for node in nodes:
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module.split(".")[0] in PACKAGES:
            yield node.module, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in PACKAGES:
                    yield a.name, []


def _target(module, name):
    """The module an import refers to: ``from a.b import c`` is module a.b.c when that exists."""
    return f"{module}.{name}" if f"{module}.{name}" in MODULES else module


def _folder(module):
    parts = module.split(".")
    return parts[1] if parts[0] == "cdpr_control" and len(parts) > 2 else None


def test_no_relative_imports():
    """Absolute imports only: a module's imports read the same wherever the module lives."""
    relative = [f"{path.relative_to(ROOT)}:{node.lineno}" for path, tree in MODULES.values()
                for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.level]
    assert not relative, relative


def test_every_library_module_lives_in_a_folder_of_fig_3_4():
    flat = [m for m in MODULES if m.startswith("cdpr_control.") and len(m.split(".")) == 2
            and m.split(".")[1] not in LAYERS]
    assert not flat, f"modules outside the folders {sorted(LAYERS)}: {flat}"
    folders = {m.split(".")[1] for m in MODULES if m.startswith("cdpr_control.") and len(m.split(".")) > 2}
    assert folders <= set(LAYERS), folders - set(LAYERS)


def test_nodes_holds_only_node_modules_each_with_its_entry_point():
    """nodes/ is one file per node (a main() and a console script of the same name), nothing else."""
    scripts = tomllib.loads((ROOT / "cdpr_control" / "pyproject.toml").read_text())["project"]["scripts"]
    targets = {v.split(":")[0] for v in scripts.values()}
    nodes = {m for m in MODULES if m.startswith("cdpr_control.nodes.")}
    assert nodes, "no node modules found"
    for module in nodes:
        tree = MODULES[module][1]
        assert any(isinstance(n, ast.FunctionDef) and n.name == "main" for n in tree.body), f"{module}: no main()"
        assert module in targets, f"{module}: no console script"


def test_imports_go_down_the_layers():
    upward = []
    for module, (path, tree) in MODULES.items():
        rank = PACKAGE_RANK[module.split(".")[0]]
        folder = _folder(module)
        for imported, names in _imports(tree):
            targets = {_target(imported, n) for n in names} or {imported}
            for target in targets:
                if PACKAGE_RANK[target.split(".")[0]] > rank:
                    upward.append(f"{module} -> {target}")
                other = _folder(target)
                if folder and other and LAYERS[other] > LAYERS[folder]:
                    upward.append(f"{module} ({folder}) -> {target} ({other})")
    assert not upward, "\n".join(upward)


def test_no_import_cycle():
    """Tarjan's strongly connected components of the module-level import graph: all of size one."""
    graph = {m: set() for m in MODULES}
    for module, (_, tree) in MODULES.items():
        for imported, names in _imports(tree, top_level_only=True):
            for target in ({_target(imported, n) for n in names} or {imported}):
                if target in MODULES and target != module:
                    graph[module].add(target)
                # importing a.b.c runs a/__init__ and a/b/__init__ first
                parent = target.rsplit(".", 1)[0]
                while "." in parent and parent in MODULES and parent != module and not module.startswith(parent + "."):
                    graph[module].add(parent)
                    parent = parent.rsplit(".", 1)[0]
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    assert not cycles, cycles


@pytest.mark.parametrize("package", PACKAGES)
def test_no_private_name_is_imported_from_another_folder(package):
    private = []
    for module, (path, tree) in MODULES.items():
        if not module.startswith(package + "."):
            continue
        home = module.rsplit(".", 1)[0] if path.name != "__init__.py" else module
        for imported, names in _imports(tree):
            is_package = imported in MODULES and MODULES[imported][0].name == "__init__.py"
            source = imported if is_package else imported.rsplit(".", 1)[0]
            for name in names:
                if name.startswith("_") and not name.startswith("__") and source != home:
                    private.append(f"{module} imports {imported}.{name}")
    assert not private, "\n".join(private)
