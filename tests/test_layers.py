"""Imports only run downward, and no module imports itself back through others.

The package is layered (``docs/design.md``); a module may import from its own layer or any lower
layer, never from a higher one, and the imports between modules form no cycle.  Every
``import`` statement counts, including those inside functions (a lazy import is still a
dependency) and those under ``if TYPE_CHECKING:`` (a name for type checkers is a dependency of
the reader: the report names the results it writes from :mod:`lantern_jax.report.results`, not
from the evaluation above it).
"""

from __future__ import annotations

import ast
from pathlib import Path

import lantern_jax

PACKAGE = Path(lantern_jax.__file__).parent

#: Layers from the bottom up; each entry is a top-level module or sub-package of lantern_jax.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("core",),  # values, time, wall-clock breakdowns, family codes, checks, registries, set-up
    ("maths",),  # pure JAX maths and loop rewrites
    ("types", "io"),  # scenario, world state, observation and token types; files on disk
    # how things move, what cameras see (ray casting and the camera rigs, which the scenarios'
    # premise check runs too), how it is measured, and what the warning channel delivers (a
    # reading of the protocol's times)
    ("dynamics", "sensors.visibility", "sensors.cameras", "sensors.warning_delivery", "scoring"),
    ("scenarios",),  # roads, families, protocol variants, warnings, suites (NumPy builders)
    ("sensors",),  # the sensor table and the observation-level readings (the warning text reads
    #                the text bank, so they sit above the scenarios)
    ("policies",),  # reference planners and the registry
    ("sim",),  # one tick and the rollouts
    ("report",),  # the results as data, their tables and files, comparisons of result folders
    # evaluation, suites, stress testing, data, language diagnostics, ablations, brax env,
    # chunks, training, transfer to unseen hazards
    ("apps",),
    ("viz",),  # plots
    ("cli", "commands", "__main__"),  # the command line
)
#: The folders of the layers: every module of the package sits in one of them, but the command
#: line's entry points and the package's own ``__init__``.
LAYER_FOLDERS = ("core", "maths", "types", "io", "dynamics", "sensors", "scoring", "scenarios",
                 "policies", "sim", "report", "apps", "viz", "commands")  # fmt: skip
LAYER_OF = {name: i for i, names in enumerate(LAYERS) for name in names}


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(["lantern_jax", *parts])


def _imports(path: Path) -> set[str]:
    """Every lantern_jax module imported anywhere in the file (``from X import y`` counts as X,
    and as ``X.y`` when that is a module)."""
    tree = ast.parse(path.read_text())
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.startswith("lantern_jax"))
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.startswith("lantern_jax"):
                if node.module != "lantern_jax":  # ``from lantern_jax import m``: only m
                    out.add(node.module)
                for a in node.names:
                    sub = f"{node.module}.{a.name}"
                    if _exists(sub):
                        out.add(sub)
    return out


def _exists(module: str) -> bool:
    rel = Path(*module.split(".")[1:])
    return (PACKAGE / rel).with_suffix(".py").exists() or (PACKAGE / rel / "__init__.py").exists()


def _top(module: str) -> str:
    """The layer entry of a module: ``package.module`` where :data:`LAYERS` names it, else the
    top-level module or package."""
    parts = module.split(".")
    if len(parts) > 2 and ".".join(parts[1:3]) in LAYER_OF:
        return ".".join(parts[1:3])
    return parts[1] if len(parts) > 1 else ""


def _graph() -> dict[str, set[str]]:
    return {_module_name(p): _imports(p) for p in sorted(PACKAGE.rglob("*.py"))}


def test_every_module_sits_in_the_folder_of_its_layer():
    """The package's top level holds the layer folders and the command line's entry points only,
    so the layers show in the folders."""
    top = {
        p.stem if p.is_file() else p.name
        for p in PACKAGE.iterdir()
        if p.suffix == ".py" or (p / "__init__.py").exists()
    }
    assert top == {"__init__", "__main__", "cli", *LAYER_FOLDERS}, sorted(top)


def test_every_module_has_a_layer():
    tops = {_top(m) for m in _graph()} - {""}
    assert tops <= set(LAYER_OF), f"modules without a layer: {sorted(tops - set(LAYER_OF))}"


def test_no_upward_import():
    bad = []
    for module, deps in _graph().items():
        src = _top(module)
        if not src:
            continue
        for dep in deps:
            dst = _top(dep)
            if not dst or dst == src:
                continue
            if LAYER_OF[dst] > LAYER_OF[src]:
                bad.append(f"{module} imports {dep} (layer {LAYER_OF[dst]} > {LAYER_OF[src]})")
    assert not bad, "imports against the layer order:\n" + "\n".join(sorted(bad))


def test_no_import_cycle():
    graph = _graph()
    # Tarjan's strongly connected components; a component of more than one module is a cycle.
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w == v or w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    # A package's __init__ that re-exports its submodules is not a cycle of behaviour.
    cycles = [c for c in cycles if not _only_package_init(c, graph)]
    assert not cycles, f"import cycles: {cycles}"


def _only_package_init(component: list[str], graph: dict[str, set[str]]) -> bool:
    """True when the cycle closes only through a package ``__init__`` re-exporting submodules."""
    inits = {m for m in component if (PACKAGE / Path(*m.split(".")[1:]) / "__init__.py").exists()}
    if not inits:
        return False
    rest = [m for m in component if m not in inits]
    sub = {m: graph[m] & set(rest) for m in rest}
    return not any(sub.values())


def test_the_checker_sees_a_violation(tmp_path, monkeypatch):
    """The layer table catches a planted upward import (the check is not vacuous)."""
    bad = tmp_path / "lantern_jax"
    (bad / "dynamics").mkdir(parents=True)
    (bad / "__init__.py").write_text("")
    (bad / "dynamics" / "__init__.py").write_text("")
    (bad / "dynamics" / "oops.py").write_text("from lantern_jax.sim.step import step\n")
    (bad / "sim").mkdir()
    (bad / "sim" / "__init__.py").write_text("")
    (bad / "sim" / "step.py").write_text("from lantern_jax.dynamics.oops import step\n")
    monkeypatch.setattr(__import__(__name__), "PACKAGE", bad)
    graph = _graph()
    assert "lantern_jax.sim.step" in graph["lantern_jax.dynamics.oops"]
    try:
        test_no_upward_import()
    except AssertionError as e:
        assert "lantern_jax.dynamics.oops imports lantern_jax.sim.step" in str(e)
    else:
        raise AssertionError("an upward import went unnoticed")
    try:
        test_no_import_cycle()
    except AssertionError as e:
        assert "lantern_jax.sim.step" in str(e)
    else:
        raise AssertionError("an import cycle went unnoticed")
