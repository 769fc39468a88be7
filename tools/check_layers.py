"""Check corl's house rules: imports point down, no import cycles, no file over 500 lines.

    python tools/check_layers.py [PACKAGE_DIR]        # default: src/corl beside this script

Every module of the package is parsed with :mod:`ast` (nothing is imported) and every ``import``
and ``from ... import`` statement is collected, the ones inside functions and ``if`` blocks
included. They make the module graph: an edge ``a -> b`` means ``a`` imports ``b``; importing
``p.q.r`` also runs the ``__init__`` of ``p.q`` (unless ``a`` is inside ``p.q`` already), so that
is an edge too. Then:

* **upward import**: each module belongs to a layer of :data:`LAYERS` (lowest first, the longest
  declared prefix wins); a module may import its own layer and the layers below, never above;
* **cycle**: a group of modules that import each other round a circle (one line per group,
  with one circle spelled out);
* **unassigned module**: a module that no layer declares (a new package must say where it sits);
* **long file**: a file over :data:`MAX_LINES` lines (a sign that two ideas share it).

Prints one line per violation (``path:line: kind: ...``) and exits 1, or prints one ``ok`` line
and exits 0. Stdlib only, so CI can run it before anything is installed.
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import deque
from dataclasses import dataclass
from pathlib import Path

MAX_LINES = 500

# Lowest first. A layer names module prefixes: "corl.trajectory" holds corl.trajectory and every
# module below it. Derived from the code: each layer imports only the ones before it.
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("base", ("corl.errors", "corl._version", "corl.versions", "corl.checks", "corl.offscreen")),  # exceptions, versions,
    # setting checks, the offscreen backend chosen before MuJoCo is imported: nothing of corl above
    ("numerics", ("corl.numerics",)),  # jitter ladder, variance floors, log-space CDFs
    ("problem", ("corl.problem",)),  # Eq. 2-5: Task, Bounds, Proposal, Outcome, Demonstration
    ("client", ("corl.client",)),  # a client of `corl serve`: stdlib HTTP, ask/tell like a learner
    ("trajectory", ("corl.trajectory",)),  # B-splines, features, the solver of Eq. 8
    ("gp", ("corl.gp",)),  # Eq. 11-13, 16
    ("acquisition", ("corl.acquisition",)),  # Eq. 14-15, 17
    ("optimizers", ("corl.optimizers",)),  # the black-box methods behind ask / tell
    ("policies", ("corl.policies",)),  # DMPs for the DMP+PoWER baseline
    ("mujoco", ("corl.mujoco",)),  # the robot kit: features of Eq. 6 for any MJCF / URDF
    ("realise", ("corl.realise",)),  # Eq. 18 with a task
    ("loop", ("corl.loop",)),  # ask, roll out, tell
    ("learner", ("corl.config", "corl.learner", "corl.speculation", "corl.direct", "corl.parallel")),  # Algorithm 1 (its speculation, K trials out); the methods over w
    ("settings", ("corl.settings",)),  # what a task gives the methods
    ("methods", ("corl.methods",)),  # a learner by name
    ("tasks", ("corl.tasks",)),  # the synthetic benchmark, the door, tasks by name
    ("store", ("corl.store",)),  # the SQLite run store
    ("contexts", ("corl.contexts",)),  # one skill, many scenes: GPs over (theta, c), Skill.policy(c)
    ("session", ("corl.session",)),  # a learner bound to the store, exact resume
    # experiments/, by what it produces: the bricks, then what is built of them
    ("experiments.base", ("corl.experiments.backends", "corl.experiments.figures", "corl.experiments.tables")),
    ("fleet", ("corl.fleet",)),  # a stored run's trials on K worker processes or Ray actors (corl run --robots)
    ("experiments.sweep", ("corl.experiments.sweep", "corl.experiments.run_output")),  # ground truth; a run's folder
    ("experiments.studies", ("corl.experiments.synthetic", "corl.experiments.door",
                                                       "corl.experiments.contexts", "corl.experiments.context_training",
                                                       "corl.experiments.parallel")),  # Fig. 1, Fig. 3
    ("experiments.html", ("corl.experiments.html",)),  # `corl report`
    ("serve", ("corl.serve",)),  # `corl serve`: the learner over HTTP, the live dashboard
    ("experiments", ("corl.experiments",)),  # the package, and the old path of corl.methods
    ("cli.support", ("corl.progress", "corl.arguments")),  # progress display, argument checks
    ("cli", ("corl.cli",)),  # the `corl` command
    ("facade", ("corl",)),  # corl/__init__: lazy names for `corl.optimize` and friends
]


@dataclass(frozen=True)
class Edge:
    """``source`` imports ``target`` at ``line`` of ``source``'s file."""

    source: str
    target: str
    line: int
    implicit: bool = False  # the __init__ of a package on the way to the named module


def module_files(root: Path) -> dict[str, Path]:
    """Module name -> file for every ``.py`` under the package directory ``root``."""
    modules = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        modules[".".join(parts)] = path
    return modules


def _resolve_relative(module: str, is_package: bool, level: int, name: str | None) -> str:
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (level - 1)] if level > 1 else base
    return ".".join(base + ([name] if name else []))


def imports_of(module: str, path: Path, modules: dict[str, Path]) -> list[Edge]:
    """The package modules that ``module`` imports, with their lines (function-local ones too)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_package = path.name == "__init__.py"
    top = next(iter(modules)).split(".")[0]
    edges = []
    for node in ast.walk(tree):
        named: list[str] = []
        if isinstance(node, ast.Import):
            named = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            origin = (_resolve_relative(module, is_package, node.level, node.module) if node.level
                      else node.module or "")
            # `from p import q` imports the module p.q when there is one, else a name of p
            named = [f"{origin}.{a.name}" if f"{origin}.{a.name}" in modules else origin for a in node.names]
        for target in named:
            if target.split(".")[0] != top:
                continue
            edges.append(Edge(module, target, node.lineno))
            # importing a.b.c runs the __init__ of a.b too, unless the importer is inside a.b
            parts = target.split(".")
            for cut in range(2, len(parts)):
                package = ".".join(parts[:cut])
                if not (module == package or module.startswith(package + ".")):
                    edges.append(Edge(module, package, node.lineno, implicit=True))
    return list(dict.fromkeys(edges))  # `from p import a, b` names p once per line


def layer_of(module: str) -> int | None:
    """Index in :data:`LAYERS` of the longest prefix that holds ``module`` (None: undeclared)."""
    best, best_len = None, -1
    for index, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            holds = module == prefix if prefix.count(".") == 0 else (
                module == prefix or module.startswith(prefix + "."))
            if holds and len(prefix) > best_len:
                best, best_len = index, len(prefix)
    return best


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components (iterative), each sorted, in sorted order."""
    index, low, on_stack, stack, components = {}, {}, set(), [], []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            advanced = False
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                    advanced = True
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                components.append(sorted(component))
    return sorted(components)


def shortest_cycle(graph: dict[str, set[str]], start: str, within: set[str]) -> list[str]:
    """A shortest circle ``start -> ... -> start`` inside ``within`` (breadth first)."""
    parent = {start: None}
    queue = deque([start])
    while queue:
        node = queue.popleft()
        for child in sorted(graph[node] & within):
            if child == start:
                path = [node]
                while parent[path[-1]] is not None:
                    path.append(parent[path[-1]])
                return [start] + path[::-1][1:] + [start] if len(path) > 1 else [start, start]
            if child not in parent:
                parent[child] = node
                queue.append(child)
    return [start]


def check(root: Path) -> list[str]:
    """Every violation in the package at ``root``, one line each (empty: the house is in order)."""
    modules = module_files(root)
    shown = {name: _shown(path) for name, path in modules.items()}
    problems = []
    edges = [edge for name, path in modules.items() for edge in imports_of(name, path, modules)]
    graph: dict[str, set[str]] = {name: set() for name in modules}
    first: dict[tuple[str, str], int] = {}
    named: dict[tuple[str, str], int] = {}
    for edge in edges:
        if edge.target not in modules:
            problems.append(f"{shown[edge.source]}:{edge.line}: unknown module: {edge.source} imports "
                            f"{edge.target}, which is not a module of the package")
            continue
        if edge.target == edge.source:
            continue
        graph[edge.source].add(edge.target)
        first.setdefault((edge.source, edge.target), edge.line)
        if not edge.implicit:
            named.setdefault((edge.source, edge.target), edge.line)
    for name in modules:
        if layer_of(name) is None:
            problems.append(f"{shown[name]}:1: unassigned module: {name} is in no layer of "
                            "tools/check_layers.py LAYERS (declare where it sits)")
    for (source, target), line in sorted(named.items()):
        low, high = layer_of(source), layer_of(target)
        if low is not None and high is not None and high > low:
            problems.append(f"{shown[source]}:{line}: upward import: {source} ({LAYERS[low][0]}) imports "
                            f"{target} ({LAYERS[high][0]}), a higher layer")
    for component in strongly_connected(graph):
        if len(component) == 1 and component[0] not in graph[component[0]]:
            continue
        circle = shortest_cycle(graph, component[0], set(component))
        steps = ", ".join(f"{a} -> {b} at line {first[(a, b)]}" for a, b in zip(circle, circle[1:]))
        others = [m for m in component if m not in circle]
        extra = f" (the group also holds {', '.join(others)})" if others else ""
        problems.append(f"{shown[component[0]]}:{first[(circle[0], circle[1])]}: import cycle: "
                        f"{' -> '.join(circle)} ({steps}){extra}")
    for name, path in modules.items():
        lines = len(path.read_text(encoding="utf-8").splitlines())
        if lines > MAX_LINES:
            problems.append(f"{shown[name]}:{lines}: long file: {lines} lines, more than {MAX_LINES}")
    return problems


def _shown(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    default = Path(__file__).resolve().parent.parent / "src" / "corl"
    parser.add_argument("package", nargs="?", type=Path, default=default, help="the package directory")
    args = parser.parse_args(argv)
    if not (args.package / "__init__.py").is_file():
        print(f"error: {args.package} is not a package directory (no __init__.py); "
              "give the path of src/corl", file=sys.stderr)
        return 2
    problems = check(args.package)
    for line in problems:
        print(line)
    if problems:
        return 1
    count = len(module_files(args.package))
    print(f"ok: {count} modules in {len(LAYERS)} layers, imports point down, no cycles, "
          f"no file over {MAX_LINES} lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
