"""The package's import graph (issue 23): no cycles, no arrow back up, no private names across modules.

The graph is read from the source with :mod:`ast` (nothing is imported), over every module of
``identifier``, ``rotor_env`` and ``agents``; imports inside functions (lazy imports) count as
much as those at the top, since they close the same loops at run time. ``from pkg import name``
is followed through the package's ``__init__`` to the module that defines ``name``.

``python tests/test_import_graph.py`` prints the counts and every offending arrow.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("identifier", "rotor_env", "agents")

#: Layers, lowest first: a module may import its own layer and those below, never one above.
#: A unit is a top-level module of ``rotor_env`` or one of its sub-packages; the first
#: prefix that matches a module's name gives its unit.
LAYERS: tuple[tuple[str, ...], ...] = (
    # generic numerics: knows nothing about rotors
    ("identifier",),
    # the declarations and the file writer everything shares
    ("rotor_env.effects", "rotor_env.params", "rotor_env.outputs", "rotor_env.results", "rotor_env.progress",
     "rotor_env.pages"),
    # data in: the ten columns, rig descriptions, readers of files and streams
    ("rotor_env.measurements",),
    # the model: regression, simulation, the on-line identification engine
    ("rotor_env.regression", "rotor_env.simulator", "rotor_env.reference", "rotor_env.slow_roll",
     "rotor_env.online", "rotor_env.rig_simulation"),
    # what is built on the model: diagnosis, monitoring, environments and their wrapper
    # figures: they draw what the layers below computed
    ("rotor_env.plots",),
    ("rotor_env.diagnosis", "rotor_env.monitor", "rotor_env.envs", "rotor_env.wrappers",
     "rotor_env.paper", "rotor_env.effects_doc", "rotor_env.batch", "rotor_env.fleet", "rotor_env.balance",
     "rotor_env.ray_cluster", "rotor_env.warmup"),
    # the command line and the tour
    ("rotor_env.cli", "rotor_env.walkthrough"),
    # the package facade (rotor_env/__init__.py)
    ("rotor_env",),
    # controllers, on top of everything
    ("agents",),
)

#: Units that must stay free of Gymnasium: the numerics, the readers, the model, the on-line
#: engine, the diagnosis and the monitor import neither the environments nor the wrappers
#: (nor gymnasium itself), so that the reinforcement-learning stack is never on their path
#: (the package facade, ``rotor_env/__init__.py``, still imports the wrappers for its users).
GYMNASIUM_FREE = ("identifier", "rotor_env.effects", "rotor_env.params", "rotor_env.outputs", "rotor_env.results",
                  "rotor_env.pages", "rotor_env.plots",
                  "rotor_env.progress", "rotor_env.balance",
                  "rotor_env.measurements", "rotor_env.regression", "rotor_env.simulator",
                  "rotor_env.online", "rotor_env.diagnosis", "rotor_env.monitor", "rotor_env.batch",
                  "rotor_env.fleet")
GYMNASIUM_UNITS = ("rotor_env.envs", "rotor_env.wrappers")


def _modules() -> dict[str, tuple[Path, bool]]:
    found = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            if is_package:
                parts = parts[:-1]
            found[".".join(parts)] = (path, is_package)
    return found


MODULES = _modules()


@cache
def _raw_imports(module: str) -> tuple[tuple[int, str, str | None], ...]:
    """``(line, imported module, imported name or None)`` for every import statement of ``module``."""
    path, is_package = MODULES[module]
    base = module.split(".") if is_package else module.split(".")[:-1]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                target = ".".join(base[: len(base) - node.level + 1] + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found += [(node.lineno, target, alias.name) for alias in node.names]
    return tuple(found)


def _ours(name: str) -> bool:
    return name.split(".")[0] in PACKAGES


def _resolve(module: str, name: str | None, seen: frozenset = frozenset()) -> str | None:
    """The module that ``from module import name`` (or ``import module``) really reaches."""
    if name is not None and f"{module}.{name}" in MODULES:
        return f"{module}.{name}"
    if module in MODULES and MODULES[module][1] and name is not None and (module, name) not in seen:
        for _, source, imported in _raw_imports(module):
            if imported == name and _ours(source):  # re-exported by the package's __init__
                return _resolve(source, imported, seen | {(module, name)})
    while module not in MODULES and "." in module:
        module = module.rsplit(".", 1)[0]
    return module if module in MODULES else None


@cache
def edges() -> tuple[tuple[str, str, str | None, int], ...]:
    """``(importer, imported module, imported name, line)`` over our packages."""
    found = []
    for module in MODULES:
        for line, source, name in _raw_imports(module):
            if _ours(source):
                target = _resolve(source, name)
                if target is not None and target != module:
                    found.append((module, target, name, line))
    return tuple(found)


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for succ in sorted(graph.get(node, ())):
            if succ not in index:
                visit(succ)
                low[node] = min(low[node], low[succ])
            elif succ in on_stack:
                low[node] = min(low[node], index[succ])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return components


def module_cycles() -> list[list[str]]:
    graph: dict[str, set[str]] = {}
    for importer, target, _, _ in edges():
        graph.setdefault(importer, set()).add(target)
    return _cycles(graph)


def unit(module: str) -> str:
    """The layer unit of ``module``: the longest prefix named in :data:`LAYERS`."""
    best = None
    for layer in LAYERS:
        for prefix in layer:
            if (module == prefix or module.startswith(prefix + ".")) and (best is None or len(prefix) > len(best)):
                best = prefix
    assert best is not None, f"{module} is in no layer of LAYERS: place it there"
    return best


def layer(module: str) -> int:
    u = unit(module)
    return next(i for i, names in enumerate(LAYERS) if u in names)


def unit_cycles() -> list[list[str]]:
    """Cycles between units (sub-packages and top-level modules), e.g. ``io`` <-> ``measurements``."""
    graph: dict[str, set[str]] = {}
    for importer, target, _, _ in edges():
        # the facade imports every unit by design; an import *of* the facade is an arrow up
        if unit(importer) != unit(target) and unit(importer) != "rotor_env":
            graph.setdefault(unit(importer), set()).add(unit(target))
    return _cycles(graph)


def upward_arrows() -> list[tuple[str, str, str]]:
    """``(importer:line, imported module, why)`` for every import of a higher layer, and every
    import of Gymnasium code from a Gymnasium-free unit."""
    found = []
    for importer, target, _, line in edges():
        if layer(target) > layer(importer):
            found.append((f"{importer}:{line}", target, f"layer {layer(importer)} -> {layer(target)}"))
        elif unit(importer) in GYMNASIUM_FREE and unit(target) in GYMNASIUM_UNITS:
            found.append((f"{importer}:{line}", target, "Gymnasium code from a Gymnasium-free unit"))
    for module in MODULES:
        if unit(module) in GYMNASIUM_FREE:
            for line, source, _ in _raw_imports(module):
                if source.split(".")[0] == "gymnasium":
                    found.append((f"{module}:{line}", source, "Gymnasium from a Gymnasium-free unit"))
    return sorted(set(found))  # one per import statement (``from m import a, b`` is one arrow)


def private_imports() -> list[str]:
    """Names with a leading underscore (or modules so named) imported from another module."""
    found = []
    for importer, target, name, line in edges():
        private_module = any(part.startswith("_") and not part.startswith("__") for part in target.split("."))
        private_name = name is not None and name.startswith("_") and not name.startswith("__")
        if private_module or private_name:
            found.append(f"{importer}:{line} imports {target}.{name or ''}")
    return found


def test_graph_is_read():
    # the reader sees what it should: a known arrow, a lazy one, a re-export followed through __init__
    arrows = {(a, b) for a, b, _, _ in edges()}
    assert ("rotor_env.regression", "identifier.recursive_qr") in arrows
    assert ("rotor_env.diagnosis.workflow", "rotor_env.diagnosis.compare") in arrows
    assert ("rotor_env.cli", "rotor_env.monitor.cli") in arrows  # imported inside build_parser
    # ``from .diagnosis import diagnose`` (inside diagnose_file) reaches the defining module
    assert ("rotor_env.batch", "rotor_env.diagnosis.workflow") in arrows
    assert len(MODULES) > 60 and len(arrows) > 200
    # units and layers: a sub-package is one unit, the layers order the map
    assert unit("rotor_env.diagnosis.compare") == "rotor_env.diagnosis"
    assert layer("identifier.kernels") < layer("rotor_env.measurements.files") < layer("rotor_env.online") \
        < layer("rotor_env.diagnosis.workflow") < layer("rotor_env.cli") < layer("agents.rllib")
    # a small graph with a known cycle
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles():
    assert module_cycles() == []
    assert unit_cycles() == []


def test_no_arrow_back_up():
    assert upward_arrows() == []


def test_no_private_names_across_modules():
    assert private_imports() == []


if __name__ == "__main__":
    cycles, units, upward, private = module_cycles(), unit_cycles(), upward_arrows(), private_imports()
    print(f"modules {len(MODULES)}, arrows {len({(a, b) for a, b, _, _ in edges()})}")
    print(f"module cycles {len(cycles)}: {cycles}")
    print(f"unit cycles {len(units)}: {units}")
    print(f"upward arrows {len(upward)}:", *(f"{w} imports {t}: {why}" for w, t, why in upward), sep="\n  ")
    print(f"private cross-module imports {len(private)}:", *private, sep="\n  ")
