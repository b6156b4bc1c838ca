"""The house rules: each package one floor that imports only the floors below it, no import
cycle, project imports at the top of a module (lazy only where laziness is the point), the
studies on the public interface, and every index of the engine's vectors read from its one
home."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path
from typing import Final, NamedTuple

import pytest

ROOT = Path(__file__).resolve().parents[1]
FLOORS = ("drill_env", "baselines", "agents", "experiments")
"""From the bottom up: a package may import the ones before it, never those after."""


def _imports(path: Path) -> set[str]:
    """Top-level packages and modules imported anywhere in ``path`` (also inside functions)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def _sources(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


LAZY_IMPORTS: Final[dict[tuple[str, str], str]] = {
    ("agents.train", "agents.vec_env"): "imports Stable-Baselines3, the optional [rl] extra",
    ("agents.train", "agents.ppo"): "imports Stable-Baselines3 and torch, the optional [rl] extra",
    ("experiments.cli", "drill_env.validation"): "loads NumPy and Numba: experiments.preflight "
    "refuses a path no command can use before that",
    ("experiments.cli", "experiments.arguments"): "loads drill_env (NumPy, Numba): "
    "experiments.preflight refuses a path no command can use before that",
}
"""The function-local project imports allowed, (importer, imported) -> why the import is lazy.
The subcommands of ``drill-gym`` are loaded by name (``importlib``), not by an import
statement."""


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


class ProjectImport(NamedTuple):
    """One import statement of a project module that names another project module."""

    importer: str
    imported: str
    line: int
    in_function: bool


def _project_imports() -> list[ProjectImport]:
    """Every import of a project module by another, at the top, under ``TYPE_CHECKING`` or
    inside a function (an imported name counts as its module when it is one)."""
    modules = {_module_name(path): path for package in FLOORS for path in _sources(package)}

    def owner(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    found: list[ProjectImport] = []
    for module, path in modules.items():
        package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]

        def visit(
            node: ast.AST, in_function: bool, module: str = module, package: list[str] = package
        ) -> None:
            for child in ast.iter_child_nodes(node):
                inner = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
                names: list[str] = []
                if isinstance(child, ast.Import):
                    names = [alias.name for alias in child.names]
                elif isinstance(child, ast.ImportFrom):
                    base = child.module or ""
                    if child.level:
                        stem = package[: len(package) - child.level + 1]
                        base = ".".join([*stem, base] if base else stem)
                    names = [base, *(f"{base}.{alias.name}" for alias in child.names)]
                for target in {owner(name) for name in names} - {None, module}:
                    found.append(ProjectImport(module, str(target), child.lineno, in_function))
                visit(child, inner)

        visit(ast.parse(path.read_text(), filename=str(path)), False)
    return found


def import_cycles(edges: set[tuple[str, str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    graph: dict[str, set[str]] = {}
    for a, b in edges:
        graph.setdefault(a, set()).add(b)
        graph.setdefault(b, set())
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return cycles


def test_the_cycle_finder_finds_cycles() -> None:
    edges = {("a", "b"), ("b", "c"), ("c", "a"), ("c", "d"), ("d", "e")}
    assert import_cycles(edges) == [["a", "b", "c"]]
    assert import_cycles({("a", "b"), ("b", "c")}) == []


def test_no_import_cycle() -> None:
    """No cycle among the project's modules, counting ``TYPE_CHECKING`` and function-local
    imports."""
    cycles = import_cycles({(i.importer, i.imported) for i in _project_imports()})
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_project_imports_are_at_the_top() -> None:
    """A project import inside a function only where laziness is the point (see
    :data:`LAZY_IMPORTS`)."""
    offenders = [
        f"{i.importer}:{i.line} imports {i.imported} inside a function"
        for i in _project_imports()
        if i.in_function and (i.importer, i.imported) not in LAZY_IMPORTS
    ]
    assert not offenders, "\n".join(offenders)
    used = {(i.importer, i.imported) for i in _project_imports() if i.in_function}
    assert set(LAZY_IMPORTS) <= used, f"stale entries: {sorted(set(LAZY_IMPORTS) - used)}"


@pytest.mark.parametrize("floor", range(len(FLOORS)), ids=FLOORS)
def test_no_package_imports_a_higher_floor(floor: int) -> None:
    package, higher = FLOORS[floor], FLOORS[floor + 1 :]
    offenders = [
        f"{path.relative_to(ROOT)} imports {name}"
        for path in _sources(package)
        for name in _imports(path)
        if name.split(".")[0] in higher
    ]
    assert not offenders, "\n".join(offenders)


def test_studies_use_the_public_interface_only() -> None:
    """The studies use gym.make/make_vec, rollout and the registry, never the engine."""
    internal = ("drill_env.batch", "drill_env.kernel", "drill_env.layout")
    offenders = [
        f"{path.relative_to(ROOT)} imports {name}"
        for path in _sources("experiments")
        for name in _imports(path)
        if name in internal
    ]
    assert not offenders, "\n".join(offenders)
    for path in _sources("experiments"):
        text = path.read_text()
        assert ".batch." not in text and "REC_" not in text, path


def test_plant_vector_is_read_by_name() -> None:
    """The compiled physics reads the plant parameter vector through ``layout.P_*``."""
    for name in ("dynamics.py", "integration.py", "kernel.py"):
        text = (ROOT / "drill_env" / name).read_text()
        assert not re.search(r"\bp\[\d", text), f"drill_env/{name} indexes p with a bare number"


def test_records_and_reports_are_read_by_name() -> None:
    """No module picks a column of the records (their third axis) or of the report (its
    second) with a bare number."""
    pattern = re.compile(
        r"\b(records|rec)\[[^\],]*,[^\],]*,\s*\d+\s*\]|\b(report|rep)\[[^\],]*,\s*\d+\s*\]"
    )
    for package in FLOORS:
        for path in _sources(package):
            for k, line in enumerate(path.read_text().splitlines(), 1):
                assert not pattern.search(line), f"{path.relative_to(ROOT)}:{k}: {line.strip()}"


def _fresh_python(code: str) -> str:
    """What ``code`` prints in a new interpreter (modules already imported here do not count)."""
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    return out.stdout.strip()


def test_importing_the_core_loads_no_higher_floor_nor_plotting() -> None:
    """``import drill_env`` and a direct-mode env pull in no controllers, agents, studies,
    plotting or torch."""
    code = (
        "import sys, gymnasium as gym, drill_env\n"
        "env = gym.make('DrillString-v0'); env.reset(seed=0); env.step(env.action_space.sample())\n"
        "bad = [m for m in ('baselines', 'agents', 'experiments', 'matplotlib', 'tqdm', 'torch',"
        " 'stable_baselines3') if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    assert _fresh_python(code) == ""


def test_the_commands_load_matplotlib_only_to_draw() -> None:
    """Every module of ``experiments`` (each ``drill-gym`` command) imports without matplotlib,
    which the figure functions import when they draw: a command's start, its argument errors
    and a ``--no-plots`` run do not wait for it (about a second)."""
    code = (
        "import importlib, pkgutil, sys, experiments\n"
        "for module in pkgutil.iter_modules(experiments.__path__):\n"
        "    importlib.import_module('experiments.' + module.name)\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'matplotlib'))\n"
    )
    assert _fresh_python(code) == "[]"


def test_a_controller_name_is_found_without_importing_baselines() -> None:
    """The core finds a built-in controller by name through the registry's entry points."""
    code = (
        "import gymnasium as gym, drill_env\n"
        "env = gym.make('DrillString-v0', base_controller='proposed')\n"
        "print(type(env.unwrapped.batch.controllers[0]).__module__)\n"
    )
    assert _fresh_python(code) == "baselines.proposed"


# --------------------------------------------------------------------- one home per fact
ENV_IDS_HOME: Final = "drill_env/ids.py"
"""The one module that spells the env ids; everything else imports them."""

CONTROLLER_LISTS_ALLOWED: Final[dict[str, str]] = {
    "experiments/realism.py:SPEED_LOOPS": "the loops whose margins the study derives",
    "experiments/coupled_controllers.py:TORQUE_LOOPS": "the study's default choice of loops",
}
"""Literal tuples, lists or sets of built-in controller names allowed, ``path:name`` -> why
(families, full-state needs, rig loops and reference controllers come from
:mod:`baselines.registry`)."""

SEVERITY_LITERALS_ALLOWED: Final[dict[str, str]] = {
    "experiments/plots.py:SEVERITY_LIMIT": "the top of the maps' colour scale, not a threshold",
    "agents/config.py:validation_severity_weight": "a weight of the selection score",
    "agents/train.py:severity_weight": "the same weight, as an argument",
}
"""Numbers bound to a severity name outside :mod:`drill_env.metrics`, ``path:name`` -> why."""


def _docstrings(tree: ast.AST) -> set[int]:
    """The ``id`` of every docstring constant (module, class, function, attribute)."""
    found: set[int] = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if not isinstance(body, list):
            continue
        for k, statement in enumerate(body):
            is_doc = isinstance(statement, ast.Expr) and isinstance(statement.value, ast.Constant)
            if is_doc and (k == 0 or isinstance(body[k - 1], ast.Assign | ast.AnnAssign)):
                found.add(id(statement.value))
    return found


def _package_trees() -> list[tuple[str, ast.Module]]:
    return [
        (str(path.relative_to(ROOT)), ast.parse(path.read_text(), filename=str(path)))
        for package in FLOORS
        for path in _sources(package)
    ]


def _bound_name(tree: ast.Module, node: ast.AST) -> str:
    """The name a top-level or class-level assignment containing ``node`` binds, or the line."""
    for statement in ast.walk(tree):
        if isinstance(statement, ast.Assign | ast.AnnAssign) and any(
            n is node for n in ast.walk(statement)
        ):
            targets = statement.targets if isinstance(statement, ast.Assign) else [statement.target]
            names = [t.id for t in targets if isinstance(t, ast.Name)]
            if names:
                return names[0]
    return f"line {getattr(node, 'lineno', '?')}"


def test_env_ids_are_spelled_in_one_place() -> None:
    """An env id as a string literal (docstrings aside) only in :data:`ENV_IDS_HOME`."""
    from drill_env.ids import COUPLED_ENV_ID, ENV_ID, FIELD_ENV_ID

    ids = {ENV_ID, FIELD_ENV_ID, COUPLED_ENV_ID}
    offenders = [
        f"{path}:{node.lineno}: {node.value!r}"
        for path, tree in _package_trees()
        if path != ENV_IDS_HOME
        for docs in [_docstrings(tree)]
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and node.value in ids and id(node) not in docs
    ]
    assert not offenders, "import the id from drill_env.ids:\n" + "\n".join(offenders)


def test_controller_names_are_not_listed_by_hand() -> None:
    """No literal tuple, list or set of two or more built-in controller names: the families
    and the rest are read from :mod:`baselines.registry`."""
    from baselines.registry import BUILT_IN

    offenders = []
    for path, tree in _package_trees():
        if path == "baselines/registry.py":
            continue
        for node in ast.walk(tree):
            if not isinstance(node, ast.Tuple | ast.List | ast.Set):
                continue
            names = [
                e.value for e in node.elts if isinstance(e, ast.Constant) and e.value in BUILT_IN
            ]
            key = f"{path}:{_bound_name(tree, node)}"
            if len(names) >= 2 and key not in CONTROLLER_LISTS_ALLOWED:
                offenders.append(f"{path}:{node.lineno}: {names}")
    assert not offenders, "read the registry (baselines.registry):\n" + "\n".join(offenders)
    assert len(CONTROLLER_LISTS_ALLOWED) <= 3


def test_severity_thresholds_have_one_home() -> None:
    """A number bound to a severity name (a constant or a default argument) only in
    :mod:`drill_env.metrics`."""
    offenders = []
    for path, tree in _package_trees():
        if path == "drill_env/metrics.py":
            continue
        for node in ast.walk(tree):
            pairs: list[tuple[str, ast.AST | None]] = []
            if isinstance(node, ast.Assign):
                pairs = [(t.id, node.value) for t in node.targets if isinstance(t, ast.Name)]
            elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
                pairs = [(node.target.id, node.value)]
            elif isinstance(node, ast.arguments):
                positional = [*node.posonlyargs, *node.args]
                defaults = [None] * (len(positional) - len(node.defaults)) + list(node.defaults)
                pairs = [(a.arg, d) for a, d in zip(positional, defaults, strict=True)]
                pairs += [
                    (a.arg, d) for a, d in zip(node.kwonlyargs, node.kw_defaults, strict=True)
                ]
            for name, value in pairs:
                number = isinstance(value, ast.Constant) and type(value.value) in (int, float)
                if (
                    number
                    and "severity" in name.lower()
                    and f"{path}:{name}" not in (SEVERITY_LITERALS_ALLOWED)
                ):
                    offenders.append(
                        f"{path}:{node.lineno if hasattr(node, 'lineno') else '?'}: {name}"
                    )
    assert not offenders, "read the threshold from drill_env.metrics:\n" + "\n".join(offenders)
