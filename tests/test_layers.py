"""The import direction of docs/architecture.md, checked on the source (every import, lazy ones included).

labtool -> campaign, identification -> reports -> processing, acquisition -> models -> common; inside models:
study -> dynamics -> mechanism. A module may import its own package and the layers below it, never
a layer above or beside it, and no group of modules may import each other in a cycle (a lazy import
inside a function counts: it only hides the cycle from Python, not from a reader).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# rank of each first-party package: a module may import ranks strictly below its own, or its own
# package. Packages of the same rank do not import each other.
RANK = {
    "common": 0,
    "models.mechanism": 1,
    "models.dynamics": 2,
    "models.study": 3,
    "models": 3,                 # models/__init__ and labtool.models.data
    "acquisition": 4,
    "processing": 4,
    # execution backends of sweeps (chunks on local processes or Dask, results streamed to disk):
    # above models, which must not import them; beside acquisition and processing
    "execution": 4,
    "reports": 5,
    "campaign": 6,               # wires acquisition, processing and reports for many points
    "identification": 6,         # labtool fit: imports reports, processing, models; only labtool imports it
    "labtool": 7,
}
# the folders installed as labtool's sub-packages (labtool.models lives in models/, ...)
SUBPACKAGES = {"common", "models", "acquisition", "processing", "execution", "reports", "campaign", "identification"}

# Known wrong-way imports and cycles, to be removed, never added to.
KNOWN_UPWARD: set[tuple[str, str]] = set()
KNOWN_CYCLES: list[set[str]] = []


def _modules() -> dict[str, Path]:
    mods = {}
    for top in SUBPACKAGES | {"labtool"}:
        for path in sorted((ROOT / top).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            if top != "labtool":
                parts.insert(0, "labtool")
            mods[".".join(parts)] = path
    return mods


def _imports(path: Path, name: str, is_package: bool) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.add(mod)
            out.update(f"{mod}.{a.name}" for a in node.names)   # 'from models import rigid'
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "import_module":
            if node.args and isinstance(node.args[0], ast.Constant):
                out.add(node.args[0].value)
    return {m for m in out if m.split(".")[0] == "labtool"}


def _layer(module: str) -> str:
    parts = module.split(".")
    if len(parts) > 1 and parts[1] in SUBPACKAGES:
        parts = parts[1:]                       # 'labtool.models.dynamics.x' -> 'models.dynamics.x'
    else:
        return "labtool"
    if parts[0] == "models" and len(parts) > 1 and f"models.{parts[1]}" in RANK:
        return f"models.{parts[1]}"
    return parts[0]


def _graph():
    mods = _modules()
    graph = {}
    for name, path in mods.items():
        targets = set()
        for imp in _imports(path, name, path.name == "__init__.py"):
            # resolve to the longest known module name ('labtool.models.dynamics.rigid.Phase' -> module)
            parts = imp.split(".")
            while parts and ".".join(parts) not in mods:
                parts.pop()
            if parts:
                targets.add(".".join(parts))
        graph[name] = targets - {name}
    return graph


def test_every_first_party_package_has_a_layer():
    unknown = {_layer(m) for m in _modules()} - set(RANK)
    assert not unknown, f"give these packages a rank in RANK (docs/architecture.md layers): {sorted(unknown)}"


@pytest.mark.slow
def test_imports_point_down_the_layers():
    wrong = set()
    for src, targets in _graph().items():
        for dst in targets:
            a, b = _layer(src), _layer(dst)
            if a == b or dst == "labtool.models" and a.startswith("models"):
                continue
            if RANK[b] >= RANK[a] and not (src, dst) in KNOWN_UPWARD:
                wrong.add((src, dst))
    assert not wrong, "imports against the layer direction (docs/architecture.md):\n" + "\n".join(
        f"  {s} -> {d}" for s, d in sorted(wrong))


def _cycles(graph) -> list[set[str]]:
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(comp)

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


@pytest.mark.slow
def test_no_import_cycles():
    graph = _graph()
    # a package's __init__ re-exporting from its own modules is not a cycle of the design
    mods = _modules()
    for name in list(graph):
        if mods[name].name == "__init__.py":
            graph[name] = {t for t in graph[name] if not t.startswith(name + ".")}
    cycles = [c for c in _cycles(graph) if c not in KNOWN_CYCLES]
    assert not cycles, "modules importing each other in a cycle:\n" + "\n".join(
        "  " + " <-> ".join(sorted(c)) for c in cycles)


@pytest.mark.parametrize("bad", ["from labtool.reports.metrics import iso_rating", "import labtool.cli"])
def test_the_checker_sees_a_wrong_way_import(tmp_path, bad):
    fake = tmp_path / "models" / "mechanism"
    fake.mkdir(parents=True)
    (fake / "probe.py").write_text(f"def f():\n    {bad}\n")
    names = _imports(fake / "probe.py", "labtool.models.mechanism.probe", False)
    layers = {_layer(n) for n in names}
    assert any(RANK[l] > RANK["models.mechanism"] for l in layers)


def test_the_checker_sees_a_cycle():
    graph = {"labtool.models.dynamics.a": {"labtool.models.dynamics.b"}, "labtool.models.dynamics.b": {"labtool.models.dynamics.c"},
             "labtool.models.dynamics.c": {"labtool.models.dynamics.a"}, "labtool.models.dynamics.d": {"labtool.models.dynamics.a"}}
    assert _cycles(graph) == [{"labtool.models.dynamics.a", "labtool.models.dynamics.b", "labtool.models.dynamics.c"}]
