"""The import graph of ctrplan: no circle, and no import up the layers.

Read from the sources with Python's ``ast`` (every import statement, also those inside
functions, which is where a circle usually hides), without importing the package.
"""

from __future__ import annotations

import ast
import collections
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "ctrplan"

#: Layers of the package's components, lowest first. A module may import from its own component
#: and from components of lower layers only (never from another component of its own layer).
LAYERS = (
    ("registry",),                             # the one registry type (imports nothing of the package)
    ("errors", "constants", "choices", "models", "planner_info",  # planner_info: names only, no OMPL
     "_log"),                                  # logging helpers (levels, the deprecated echo)
    ("parallel", "cache"),                     # the one executor (this process, local workers or Dask);
                                               # the one rule of keys of stored results
    ("history",),                              # pure numerics of motion history
    ("robot", "calibration"),                  # calibration: the robot file's records of measurements, typed
    ("coordinates", "effects", "drive"),       # robot-level quantities, the registry of effects, the
                                               # joints' and the drive's limits
    ("obstacles",),                            # obstacle types and their registry: the scenario loader (io),
                                               # the collision checker (planning) and the plots use them
    ("io",),                                   # files -> robots, scenarios, tables
    ("mechanics",),                            # the models and the bound
    ("batch", "boundmap", "trajectory"),
    ("plots",),                                # figure helpers shared by every report
    ("discrepancy", "planning"),               # planning: the search's building blocks, a module per stage
                                               # of a plan, and the plan's outputs package
    ("design", "pipeline"),                    # experiment design from a discrepancy run's results;
                                               # pipeline: the former home of the stages (names only)
    ("api",),                                  # ctrplan.plan and plan_scenario: a plan's stages run
    ("studies", "testing"),                    # many scenarios; assertions on plans for pytest suites
    ("cli",),                                  # command line
)


#: Imports up the layers made inside a function body, when it is called, so that an entry of a
#: light registry can hold a function of a heavy component: (module, imported module).
CALL_TIME_IMPORTS = {
    ("ctrplan.models", "ctrplan.mechanics.contact"),   # the contact models' solve (models.contact_solution)
}


def _modules() -> dict:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _graph(modules: dict) -> dict:
    """Module -> the ctrplan modules it imports (a ``from X import Y`` names X.Y when that is a
    module, else X)."""
    edges = collections.defaultdict(set)
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                if not target.startswith("ctrplan"):
                    continue
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    edges[name].add(sub if sub in modules else target)
            elif isinstance(node, ast.Import):
                edges[name].update(a.name for a in node.names if a.name.startswith("ctrplan"))
    return edges


def _component(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "ctrplan"


def test_the_layers_name_every_component():
    """A new component must be given a layer (else the rule below would not see it)."""
    components = {_component(m) for m in _modules()} - {"ctrplan"}
    named = {c for layer in LAYERS for c in layer}
    assert components <= named, f"components without a layer: {sorted(components - named)}"


def test_no_import_runs_up_the_layers():
    """Catches e.g. io importing boundmap, or mechanics importing planning."""
    level = {c: k for k, layer in enumerate(LAYERS) for c in layer}
    modules = _modules()
    bad = []
    for src, targets in _graph(modules).items():
        a = _component(src)
        if a == "ctrplan":
            continue            # the package's own __init__ re-exports the public names
        for dst in targets:
            b = _component(dst)
            if b in (a, "ctrplan") or (src, dst) in CALL_TIME_IMPORTS:
                continue
            if level[b] >= level[a]:
                bad.append(f"{src} imports {dst} ({a} is in layer {level[a]}, {b} in layer {level[b]})")
    assert not bad, "\n".join(bad)


def test_imports_up_the_layers_run_only_when_called():
    """Each import of :data:`CALL_TIME_IMPORTS` is there and sits in a function body (catches
    one moved to the top of its module, which would load the heavy component on import)."""
    modules = _modules()
    for src, dst in CALL_TIME_IMPORTS:
        tree = ast.parse(modules[src].read_text(encoding="utf-8"))
        inside, everywhere = set(), set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                inside |= {id(n) for n in ast.walk(node) if isinstance(n, ast.ImportFrom)}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level and node.module \
                    and f"ctrplan.{node.module}" == dst:
                everywhere.add(id(node))
        assert everywhere, f"{src} no longer imports {dst}: remove it from CALL_TIME_IMPORTS"
        assert everywhere <= inside, f"{src} imports {dst} at module level"


def test_no_import_circle():
    """Strongly connected components of the module graph (Tarjan): none may hold two modules.
    Catches e.g. planning.planners and planning.validity importing each other."""
    modules = _modules()
    edges = _graph(modules)
    index, low, stack, on_stack, circles = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in edges.get(v, ()):
            if w not in modules:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            scc = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                scc.append(w)
                if w == v:
                    break
            if len(scc) > 1:
                circles.append(sorted(scc))

    for m in sorted(modules):
        if m not in index:
            visit(m)
    assert not circles, f"import circles: {circles}"


def test_the_graph_reader_sees_relative_and_function_level_imports(tmp_path, monkeypatch):
    """The reader itself: a relative import inside a function counts, and one running up the
    layers is reported (so a passing test above means something)."""
    pkg = tmp_path / "ctrplan"
    (pkg / "io").mkdir(parents=True)
    (pkg / "boundmap").mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "io" / "__init__.py").write_text("")
    (pkg / "boundmap" / "__init__.py").write_text("")
    (pkg / "boundmap" / "grid.py").write_text("X = 1\n")
    (pkg / "io" / "scenario.py").write_text("def f():\n    from ..boundmap.grid import X\n    return X\n")
    monkeypatch.setattr(__import__(__name__), "PACKAGE", pkg)
    modules = _modules()
    assert "ctrplan.boundmap.grid" in _graph(modules)["ctrplan.io.scenario"]


def _private_imports(modules: dict) -> set:
    """(importing module, imported module, name) of every ``from X import Y`` that reaches into
    another component through a private module (a path part starting with ``_``) or a private
    name."""
    out = set()
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if (not target.startswith("ctrplan") or _component(target) == _component(name)
                    or _component(target) == "_log"):   # the package's own logging helpers
                continue
            private_module = any(part.startswith("_") for part in target.split("."))
            for alias in node.names:
                if private_module or (alias.name.startswith("_") and f"{target}.{alias.name}" not in modules):
                    out.add((name, target, alias.name))
    return out


def test_no_component_imports_another_s_private_names():
    """A name one component uses from another is public and documented there (catches a new
    reach into a private module or name, e.g. planning importing obstacles._base's tolerance)."""
    found = _private_imports(_modules())
    assert not found, "\n".join(sorted(f"{a} imports {n} from {b}" for a, b, n in found))


def test_no_public_class_name_is_defined_twice():
    """One concept, one name: catches a second PlanResult, JointGoal or TaskGoal."""
    where = collections.defaultdict(set)
    for name, path in _modules().items():
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                where[node.name].add(name)
    twice = {c: m for c, m in where.items() if len(m) > 1}
    assert not twice, twice


#: Public function names defined in two modules that mean the same: the rivalry test of two
#: effects (one contains the other), in the discrepancy workflow's fits and its verdict.
SAME_FUNCTION_TWICE = {"contained"}


def test_no_public_function_name_is_defined_twice():
    """One name, one function: catches a second ``plan``, ``load_bound_map``, ``write_report`` or
    ``time_parameterize`` with another job (private modules, ``_name.py``, aside: their names are
    not the package's API)."""
    where = collections.defaultdict(set)
    for name, path in _modules().items():
        if path.name.startswith("_") and path.name != "__init__.py":
            continue
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.FunctionDef) and not node.name.startswith("_"):
                where[node.name].add(name)
    twice = {f: sorted(m) for f, m in where.items() if len(m) > 1 and f not in SAME_FUNCTION_TWICE}
    assert not twice, twice


#: The longest a module may be, in lines, unless it holds compiled kernels (numba functions, whose
#: helpers are inlined into each other and stay in one file so that they compile and cache together).
MAX_MODULE_LINES = 800


def _compiled(tree: ast.Module) -> bool:
    """The module defines a numba-compiled function (decorated ``njit`` or ``jit``)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef):
            for d in node.decorator_list:
                f = d.func if isinstance(d, ast.Call) else d
                if (f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")) in ("njit", "jit"):
                    return True
    return False


def test_no_module_is_longer_than_one_sitting():
    """Catches a module grown past MAX_MODULE_LINES (numba kernel modules aside)."""
    long = []
    for name, path in _modules().items():
        text = path.read_text(encoding="utf-8")
        n = text.count("\n")
        if n > MAX_MODULE_LINES and not _compiled(ast.parse(text)):
            long.append(f"{name}: {n} lines")
    assert not long, long
