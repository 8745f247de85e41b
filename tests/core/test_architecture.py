"""The dependency rules of docs/ARCHITECTURE.md: no import circle, and the layer contracts of pyproject.toml.

Both checks need grimp and import-linter (the `test` extra): when they are missing these tests fail with an
ImportError, they never skip, so a check that did not run cannot pass.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path

import grimp
import importlinter  # noqa: F401  (fail here, not in the subprocess, when the tool is missing)

PROJECT = Path(__file__).resolve().parents[2]
PACKAGES = ("onboard", "ground", "hil_sim")


def import_graph(packages: Iterable[str] = PACKAGES) -> dict[str, set[str]]:
    """Module -> modules of `packages` it imports (at any place in the file, lazy imports included)."""
    graph = grimp.build_graph(*packages, cache_dir=None)
    return {m: set(graph.find_modules_directly_imported_by(m)) for m in graph.modules}


def import_circles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (or a module importing itself), each sorted.

    Tarjan's algorithm, iterative (the graph has a few hundred modules; recursion would be fine, but no limit
    to think about).
    """
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    circles: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work: list[tuple[str, Iterable[str]]] = [(root, iter(sorted(graph.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            advanced = False
            for succ in successors:
                if succ not in index:
                    index[succ] = low[succ] = counter
                    counter += 1
                    stack.append(succ)
                    on_stack.add(succ)
                    work.append((succ, iter(sorted(graph.get(succ, ())))))
                    advanced = True
                    break
                if succ in on_stack:
                    low[node] = min(low[node], index[succ])
            if advanced:
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1 or node in graph.get(node, ()):
                    circles.append(sorted(component))
    return sorted(circles)


def describe(circle: list[str], graph: Mapping[str, set[str]]) -> str:
    """One circle as its modules and the imports between them (`a -> b`)."""
    members = set(circle)
    edges = [f"{a} -> {b}" for a in circle for b in sorted(graph.get(a, ())) if b in members]
    return f"{' <-> '.join(circle)}\n      " + "\n      ".join(edges)


def test_the_circle_finder_names_the_modules_of_a_circle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}, "f": {"d"}}
    assert import_circles(graph) == [["a", "b", "c"], ["e"]]
    assert "c -> a" in describe(["a", "b", "c"], graph)


def test_no_import_circle_in_onboard_ground_hil_sim() -> None:
    graph = import_graph()
    assert len(graph) > 100, "the import graph is suspiciously small: were the packages found?"
    circles = import_circles(graph)
    assert not circles, "import circles:\n  " + "\n  ".join(describe(c, graph) for c in circles)


def test_layer_contracts_of_pyproject() -> None:
    """import-linter's contracts (pyproject.toml [tool.importlinter]) run on this tree, every one kept."""
    # what the `lint-imports` script runs (its entry point), in this interpreter: no search for the script
    code = "from importlinter.cli import lint_imports_command; lint_imports_command()"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(PROJECT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", code, "--no-cache", "--no-logo"], cwd=PROJECT, env=env,
                          capture_output=True, text=True, timeout=300, check=False)
    out = proc.stdout + proc.stderr
    assert "Contracts:" in out and " kept" in out, out[-3000:]  # the contracts ran
    assert proc.returncode == 0, out[-4000:]
