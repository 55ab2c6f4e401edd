"""The house rules, checked on the source: no import cycles between project modules, the data flow's
layering (world -> autopilot -> link -> estimator / strategy -> runner -> recording), and file sizes.

Imports are read with ``ast`` (module level and inside functions; imports under
``if TYPE_CHECKING:`` are type hints, not dependencies, and are left out).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("sitl", "vehicle", "wire", "estimator", "mission", "recording", "review", "windseek", "identify",
            "toolchain", "urbanflow")
GENERATED = {"wire/dialect/windseek.py"}
MAX_LINES = 450

#: (importer prefix, imported prefix): imports that would break the data flow.
FORBIDDEN = [
    ("sitl.world", "sitl.autopilot"),  # the world takes rotor commands, it has no autopilot inside
    ("sitl.world", "sitl.link"),
    ("sitl.world", "sitl.hil"),  # the world knows no autopilot's simulator protocol
    ("sitl.world", "sitl.ardupilot"),
    ("sitl.hil", "sitl.ardupilot"),  # PX4's bridge needs nothing of ArduPilot's (the reverse reuses its parts)
    ("sitl", "mission"),
    ("sitl", "estimator"),
    ("vehicle", "sitl"),
    ("wire", "sitl"),
    ("estimator", "sitl"),  # the estimator runs on a real vehicle: it must not need the simulator
    ("estimator", "mission"),
    ("review", "sitl"),  # a log review must not need the simulator
    ("recording", "sitl"),  # the recorder listens; it needs no simulator to run
    ("mission.strategies", "sitl"),  # strategies see observations, never the simulator
    ("mission.strategies", "mission.runners"),
    ("mission", "windseek"),  # library layers never need the command line
    ("sitl", "windseek"),
    ("estimator", "windseek"),
    ("toolchain", "sitl"),  # the numba cache set-up sits below every layer
    ("urbanflow", "sitl"),  # the urban wind field is a pure computation below the world and the mission
    ("urbanflow", "mission"),
    ("identify", "sitl"),  # the identification runs on any flight's data; only its in-process adapter flies
]
#: (importer prefix, imported prefix) -> importers under these prefixes may: the adapters that fill the
#: data from the simulator (identify.fly.world flies the manoeuvre in windseek's world).
EXEMPT = {("identify", "sitl"): ("identify.fly",)}


def _under(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def _module(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _sources() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for f in (ROOT / pkg).rglob("*.py"):
            if f.relative_to(ROOT).as_posix() not in GENERATED:
                out[_module(f)] = f
    return out


class _Imports(ast.NodeVisitor):
    def __init__(self, module: str, is_package: bool, modules: set[str]) -> None:
        self.module, self.is_package, self.modules = module, is_package, modules
        self.found: set[str] = set()

    def visit_If(self, node: ast.If) -> None:
        test = node.test
        if (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
                isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"):  # fmt: skip
            for n in node.orelse:
                self.visit(n)
            return
        self.generic_visit(node)

    def visit_Import(self, node: ast.Import) -> None:
        self.found.update(a.name for a in node.names)

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        base = node.module or ""
        if node.level:
            pkg = self.module.split(".")
            pkg = pkg if self.is_package else pkg[:-1]
            pkg = pkg[: len(pkg) - node.level + 1]
            base = ".".join([*pkg, base] if base else pkg)
        # ``from pkg import submodule`` needs the submodule (pkg is already being imported); any
        # other name comes from ``base`` itself.
        subs = {f"{base}.{a.name}" for a in node.names}
        modules = subs & self.modules
        self.found.update(modules)
        if modules != subs:
            self.found.add(base)


def _graph() -> dict[str, set[str]]:
    src = _sources()
    graph: dict[str, set[str]] = {}
    for mod, path in src.items():
        v = _Imports(mod, path.name == "__init__.py", set(src))
        v.visit(ast.parse(path.read_text(), str(path)))
        graph[mod] = {m for m in v.found if m in src and m != mod}
    return graph


def test_no_import_cycles_between_project_modules() -> None:
    graph = _graph()
    state: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph[m]):
            if state.get(n, 0) == 0:
                visit(n)
            elif state[n] == 1:
                cycles.append(stack[stack.index(n):] + [n])
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if state.get(m, 0) == 0:
            visit(m)
    # A package's __init__ re-exporting its own submodules is not a cycle of the design.
    real = [c for c in cycles if not _reexport_only(c)]
    assert not real, "import cycles:\n" + "\n".join(" -> ".join(c) for c in real)


def _reexport_only(cycle: list[str]) -> bool:
    """A cycle through a package __init__ that only re-exports its submodules (``pkg -> pkg.mod -> pkg``)."""
    return any(b.startswith(a + ".") for a, b in zip(cycle, cycle[1:], strict=False)) and len(set(cycle)) == 2


def _path_to(graph: dict[str, set[str]], start: str, prefix: str, skip: tuple[str, ...]) -> list[str] | None:
    """The shortest import chain from ``start`` to a module under ``prefix`` (breadth first), not passing
    through modules under ``skip`` (exempt adapters), or None."""
    parent: dict[str, str] = {start: ""}
    todo = [start]
    while todo:
        nxt = []
        for m in todo:
            for n in sorted(graph[m]):
                if n in parent or any(_under(n, s) for s in skip):
                    continue
                parent[n] = m
                if _under(n, prefix):
                    chain = [n]
                    while parent[chain[-1]]:
                        chain.append(parent[chain[-1]])
                    return chain[::-1]
                nxt.append(n)
        todo = nxt
    return None


@pytest.mark.parametrize(("importer", "imported"), FORBIDDEN)
def test_layering(importer: str, imported: str) -> None:
    """Followed transitively: importing the world must not import the autopilot through the scenario parser."""
    exempt = EXEMPT.get((importer, imported), ())
    graph = _graph()
    bad = []
    for m in sorted(graph):
        if _under(m, importer) and not any(_under(m, e) for e in exempt):
            chain = _path_to(graph, m, imported, exempt)
            if chain is not None:
                bad.append(" -> ".join(chain))
    assert not bad, "\n".join(bad)


def test_layering_is_transitive() -> None:
    """The rule checker sees an indirect import (a -> b -> c) as well as a direct one."""
    graph = {"x.a": {"x.b"}, "x.b": {"y.c"}, "y.c": set()}
    assert _path_to(graph, "x.a", "y", ()) == ["x.a", "x.b", "y.c"]
    assert _path_to(graph, "x.a", "y", ("x.b",)) is None


def test_layering_exemptions_are_in_use() -> None:
    """An exemption names modules that exist and do import what the rule forbids (else it is stale), and
    the rule still has modules it binds (the identification core)."""
    graph = _graph()
    for (importer, imported), prefixes in EXEMPT.items():
        for e in prefixes:
            users = [m for m, deps in graph.items() if _under(m, e) and any(_under(n, imported) for n in deps)]
            assert users, f"exemption {e} of ({importer}, {imported}) is not used by any module"
        bound = [m for m in graph if _under(m, importer) and not any(_under(m, e) for e in prefixes)]
        assert len(bound) >= 5, bound


def test_no_project_file_over_the_size_limit() -> None:
    long = {p.relative_to(ROOT).as_posix(): n for p in _sources().values()
            if (n := len(p.read_text().splitlines())) > MAX_LINES}  # fmt: skip
    assert not long, f"files over {MAX_LINES} lines: {long}"


def test_importing_the_world_loads_no_autopilot_or_scenario_parser() -> None:
    """At run time too: a fresh interpreter that imports the world has no autopilot, link or scenario
    module loaded (the world takes a WorldSpec, not the Scenario that carries the autopilot's gains)."""
    import subprocess
    import sys

    code = ("import sys, sitl.world.world; print(sorted(m for m in sys.modules "
            "if m.startswith(('sitl.autopilot', 'sitl.scenario', 'sitl.link', 'mission', 'estimator'))))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
