"""The walk of a measurement file through ``diagnose``, and the import graph's counts (issue 23).

``python scripts/import_walk.py [ROOT] [--report] [-v]`` simulates a record (the linear Jeffcott rotor with a
shaft asymmetry, ``D = 0.03``, noise 5e-4, seed 11: the CLI tests' file), writes it as CSV
and runs ``rotor-id diagnose FILE --json`` under :func:`sys.setprofile`, with the package
imported from ``ROOT`` (default: this checkout; give an exported older commit to compare);
``--report`` adds ``--report OUT.html`` (the figures and the page), ``-v`` prints every step.

Every call from a function of one module of ``rotor_env``/``identifier`` into a function of
another is a step of the walk; a step is counted once per (caller, callee) pair of
functions, in the order first taken, so loops do not inflate it.  Printed:

* ``calls``: distinct cross-module calls (caller function -> callee function);
* ``modules``: distinct modules the walk passes through;
* ``returns``: steps into a module the walk had already left (it bounces back; a call
  down into a shared leaf, ``effects`` or ``measurements.core``, counts too);
* ``upward calls``: steps from a lower layer into a higher one (``LAYERS`` of the
  import-graph test): a callback against the map;

then the import graph's module cycles, unit cycles, upward arrows and private imports,
counted with ``tests/test_import_graph.py``'s helpers over ``ROOT``'s sources (the
layers are this checkout's).
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
PACKAGES = ("rotor_env", "identifier")


def _ours(module: str | None) -> bool:
    return bool(module) and module.split(".")[0] in PACKAGES


def walk(path: Path, *extra: str) -> tuple[list[tuple[str, str]], int]:
    """The cross-module steps ``(caller module, callee module)`` of ``diagnose FILE``, each
    (caller function, callee function) pair once, in the order first taken; and the exit code."""
    from rotor_env.cli import main

    seen: set[tuple] = set()
    steps: list[tuple[str, str]] = []

    def profile(frame, event, arg):
        if event != "call":
            return
        callee = frame.f_globals.get("__name__")
        caller_frame = frame.f_back
        if caller_frame is None:
            return
        caller = caller_frame.f_globals.get("__name__")
        if callee == caller or not (_ours(callee) and _ours(caller)):
            return
        key = (caller, caller_frame.f_code.co_name, callee, frame.f_code.co_name)
        if key not in seen:
            seen.add(key)
            steps.append((caller, callee))

    out = io.StringIO()
    sys.setprofile(profile)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
            rc = main(["diagnose", str(path), "--json", *extra])
    finally:
        sys.setprofile(None)
    return steps, rc


def walk_figures(steps: list[tuple[str, str]], layer) -> dict[str, int]:
    """``calls``, ``modules``, ``returns`` (entries into a module already left) and ``upward
    calls`` (``layer(callee) > layer(caller)``) of a walk."""
    modules: set[str] = set()
    left: set[str] = set()
    returns = 0
    current = None
    for caller, callee in steps:
        modules.update((caller, callee))
        if current is not None and caller != current:
            left.add(current)  # the walk went on from another module: the current one was left
        left.add(caller)
        if callee in left:
            returns += 1
        current = callee
    upward = sum(layer(callee) > layer(caller) for caller, callee in steps)
    return {"calls": len(steps), "modules": len(modules), "returns": returns, "upward calls": upward}


def import_graph(root: Path):
    """``tests/test_import_graph.py`` (this checkout's layers) reading ``root``'s sources."""
    spec = importlib.util.spec_from_file_location("import_graph", HERE / "tests" / "test_import_graph.py")
    graph = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(graph)
    graph.ROOT = root
    graph.MODULES = graph._modules()
    graph._raw_imports.cache_clear()
    return graph


def graph_figures(graph) -> dict[str, int]:
    """Module cycles, unit cycles, upward arrows and private imports of the graph."""
    return {"module cycles": len(graph.module_cycles()), "unit cycles": len(graph.unit_cycles()),
            "upward arrows": len(graph.upward_arrows()), "private imports": len(graph.private_imports())}


def main() -> int:
    args = [a for a in sys.argv[1:] if not a.startswith("-")]
    root = Path(args[0]).resolve() if args else HERE
    sys.path.insert(0, str(root))
    import rotor_env

    assert Path(rotor_env.__file__).resolve().is_relative_to(root), rotor_env.__file__
    from rotor_env.params import RotorParams
    from rotor_env.simulator import simulate

    jeffcott = RotorParams().replace(D=0.03, k30=0.0, k21=0.0, k12=0.0, k03=0.0, h=0.0)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "asym.csv"
        simulate(jeffcott, noise=5e-4, seed=11).to_file(path)
        extra = ("--report", str(Path(tmp) / "report.html")) if "--report" in sys.argv else ()
        steps, rc = walk(path, *extra)
    print(f"source: {root}  (exit code of diagnose: {rc})")
    graph = import_graph(root)
    print("walk of a file through diagnose" + (" --report" if "--report" in sys.argv else "") + ":",
          ", ".join(f"{k} {v}" for k, v in walk_figures(steps, graph.layer).items()))
    print("import graph:", ", ".join(f"{k} {v}" for k, v in graph_figures(graph).items()))
    if "-v" in sys.argv:
        for caller, callee in steps:
            print(f"  {caller} -> {callee}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
