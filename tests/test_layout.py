"""The package's shape: no import cycles (module-level or inside functions), no private names imported
across modules, no file over about 400 lines. Static: reads the sources, imports nothing."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = {"taichimyxo": ROOT / "taichimyxo", "taichimyxo.render": ROOT / "render"}
MAX_LINES = 420


def _modules() -> dict:
    mods = {}
    for pkg, folder in PACKAGES.items():
        for f in folder.rglob("*.py"):
            parts = f.relative_to(folder).with_suffix("").parts
            name = ".".join((pkg, *parts))
            mods[name[: -len(".__init__")] if name.endswith(".__init__") else name] = f
    return mods


def _imports(mods: dict) -> tuple[dict, list]:
    graph, private = {}, []
    for name, f in mods.items():
        pkg = name if f.name == "__init__.py" else name.rsplit(".", 1)[0]
        deps = set()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1] if node.level else []
                target = ".".join(base + ([node.module] if node.module else []))
                for a in node.names:
                    if f"{target}.{a.name}" in mods:
                        deps.add(f"{target}.{a.name}")
                    elif target in mods:
                        deps.add(target)
                        if a.name.startswith("_") and not a.name.startswith("__"):
                            private.append(f"{name} imports {target}.{a.name}")
            elif isinstance(node, ast.Import):
                deps.update(a.name for a in node.names if a.name in mods)
        deps.discard(name)
        graph[name] = deps
    return graph, private


def test_no_import_cycles_and_no_private_imports():
    graph, private = _imports(_modules())
    state, cycles = {}, []

    def visit(n, path):
        state[n] = 1
        for d in sorted(graph.get(n, ())):
            if state.get(d) == 1:
                cycles.append(" -> ".join(path[path.index(d):] + [d]))
            elif d not in state:
                visit(d, path + [d])
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [n])
    assert not cycles, cycles
    assert not private, private


def test_no_file_over_about_400_lines():
    long = {str(f.relative_to(ROOT)): n for f in _modules().values()
            if (n := len(f.read_text().splitlines())) > MAX_LINES}
    assert not long, long
