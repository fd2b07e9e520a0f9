"""The package's layers (docs/architecture.md): imports go down only, no cycles, no private names.

Read from the source with :mod:`ast` (nothing is imported), so a new module, a new import or a
helper borrowed from another module fails here with the file and line.
"""

from __future__ import annotations

import ast
import pathlib
import re
from collections import defaultdict

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[2] / "python" / "modaluq"

#: Layer of every module, lowest first (docs/architecture.md). A name ending in ``.*`` covers a
#: subpackage. A module may import modules of its own layer or below; never above.
LAYERS = {
    "modaluq._core": 0, "modaluq._dispatch": 0, "modaluq._blas": 0, "modaluq.version": 0,
    "modaluq.checks": 1, "modaluq.buildinfo": 1, "modaluq.jsonvalues": 1, "modaluq.atomic": 1,
    # settings and the signal helpers they are applied with; the side leaves (files, simulator)
    "modaluq.settings": 2, "modaluq.preprocess": 2, "modaluq.auto_settings": 2, "modaluq.spectrum": 2,
    "modaluq.indicators": 2, "modaluq.intervals": 2,
    "modaluq.harmonics": 2, "modaluq.provenance": 2, "modaluq.geometry": 2, "modaluq.simulate.*": 2, "modaluq.io.*": 2,
    "modaluq.monitoring.simulator": 2,  # the monitoring wing's campaign simulator: a side leaf
    # The result types sit above what their convenience methods reach (Result.plot() ->
    # Diagram.select_modes() -> SelectedModes.to_dict()): a module imports the types it makes and
    # takes the types it is given by their fields, so plots, formats and the functions that make
    # the next result sit below the types they take.
    "modaluq.plot": 3, "modaluq.export": 3, "modaluq.shapes": 3, "modaluq.exchange": 3, "modaluq.htmlreport": 3,
    "modaluq.selection": 4,
    "modaluq.stabilization": 5,
    "modaluq.results": 6,
    "modaluq.identification": 7, "modaluq.streaming": 7, "modaluq.poser": 7,
    "modaluq.horizons": 8, "modaluq.analysis": 8, "modaluq.campaign_analysis": 8, "modaluq.validation.*": 8,
    "modaluq.comparison": 8,
    "modaluq.monitoring.*": 9,  # the wing, many records: its modules in WING order
    "modaluq.cli.*": 10,
    "modaluq": 11,  # the package's namespace: re-exports the public API
}

#: Side leaves: they import nothing of the package but these (and their own subpackage).
SIDE_LEAVES = {"modaluq.io": {"modaluq.checks"}, "modaluq.simulate": {"modaluq.checks"},
               "modaluq.monitoring.simulator": {"modaluq.checks", "modaluq.atomic", "modaluq.simulate"}}

#: The monitoring wing's modules (docs/architecture.md), each importing only those before it;
#: its ``__init__`` (``modaluq.monitoring``) imports them all.
WING = ["modaluq.monitoring.simulator", "modaluq.monitoring.tracking", "modaluq.monitoring.change",
        "modaluq.monitoring.records", "modaluq.monitoring.parts", "modaluq.monitoring.executors",
        "modaluq.monitoring.worker", "modaluq.monitoring.store", "modaluq.monitoring.plot",
        "modaluq.monitoring.run"]


def module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def layer_of(module: str) -> int:
    if module in LAYERS:
        return LAYERS[module]
    for name, layer in LAYERS.items():
        if name.endswith(".*") and (module == name[:-2] or module.startswith(name[:-1])):
            return layer
    raise KeyError(module)


def modules() -> dict:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


class Import:
    def __init__(self, source, target, names, line, function, cls):
        self.source, self.target, self.names, self.line = source, target, names, line
        self.function, self.cls = function, cls  # enclosing function / class (None at top level)

    def __repr__(self):
        return f"{self.source}:{self.line} imports {self.target} {self.names}"


def imports_of(module: str, path: pathlib.Path, known: set) -> list:
    """Every import of a package module in ``path``, with where it sits."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []

    def visit(node, function, cls):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                visit(child, child.name, cls)
            elif isinstance(child, ast.ClassDef):
                visit(child, function, child.name if function is None else cls)
            elif isinstance(child, ast.Import):
                for a in child.names:
                    if a.name.split(".")[0] == "modaluq":
                        out.append(Import(module, a.name, [], child.lineno, function, cls))
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")
                    base = base[:len(base) - (child.level - 1)]
                    target = ".".join(base + ([child.module] if child.module else []))
                else:
                    target = child.module or ""
                if target.split(".")[0] != "modaluq":
                    continue
                names = [a.name for a in child.names]
                submodules = [f"{target}.{n}" for n in names if f"{target}.{n}" in known]
                for sub in submodules:  # from . import plot: the module plot
                    out.append(Import(module, sub, [], child.lineno, function, cls))
                rest = [n for n in names if f"{target}.{n}" not in known]
                if rest:
                    out.append(Import(module, target, rest, child.lineno, function, cls))
            else:
                visit(child, function, cls)

    visit(tree, None, None)
    return out


@pytest.fixture(scope="module")
def graph():
    mods = modules()
    known = set(mods) | {"modaluq._core"}
    return mods, [imp for m, p in mods.items() for imp in imports_of(m, p, known)]


def test_every_module_has_a_layer(graph):
    mods, _ = graph
    missing = []
    for m in mods:
        try:
            layer_of(m)
        except KeyError:
            missing.append(m)
    assert not missing, f"modules without a layer in LAYERS (and docs/architecture.md): {missing}"


def test_imports_go_down_only(graph):
    # every import, at the top of a module or inside a function or method: no exception
    _, imps = graph
    upward = [imp for imp in imps if layer_of(imp.target) > layer_of(imp.source)]
    assert not upward, f"imports of a higher layer: {upward}"


def test_no_import_cycles(graph):
    # every edge goes down or sideways; a cycle could only be among modules of one layer
    _, imps = graph
    edges = defaultdict(set)
    for imp in imps:
        if imp.target != imp.source:
            edges[imp.source].add(imp.target)
    state = {}

    def visit(m, stack):
        state[m] = "open"
        for n in sorted(edges.get(m, ())):
            if state.get(n) == "open":
                raise AssertionError(f"import cycle: {' -> '.join(stack[stack.index(n):] + [n])}")
            if n not in state:
                visit(n, stack + [n])
        state[m] = "done"

    for m in sorted(edges):
        if m not in state:
            visit(m, [m])


def test_no_private_name_crosses_a_module(graph):
    _, imps = graph
    bad = []
    for imp in imps:
        private = [n for n in imp.names if n.startswith("_") and not n.startswith("__")]
        if private and imp.target != imp.source:
            bad.append(imp)
        # a private module (_common, _blas) is used only inside its own package (and its subpackages)
        hidden = [p for p in imp.target.split(".")[1:] if p.startswith("_") and p != "__init__"]
        if hidden and not (imp.source.startswith(imp.target.rpartition(".")[0] + ".") or
                           imp.target.rpartition(".")[0] == imp.source) and imp.target != "modaluq._core":
            bad.append(imp)
    assert not bad, f"private names or modules used from another module: {bad}"


def test_side_leaves_stand_alone(graph):
    _, imps = graph
    bad = []
    for leaf, allowed in SIDE_LEAVES.items():
        for imp in imps:
            inside = imp.source == leaf or imp.source.startswith(leaf + ".")
            own = imp.target == leaf or imp.target.startswith(leaf + ".")
            if inside and not own and imp.target not in allowed and imp.target != "modaluq._core":
                bad.append(imp)
    assert not bad, f"a side leaf imports the package: {bad}"


def test_the_wing_imports_its_modules_in_order_and_nothing_imports_the_wing_at_import_time(graph):
    mods, imps = graph
    assert sorted(WING) == sorted(m for m in mods if m.startswith("modaluq.monitoring.")), \
        "a module of the wing is missing from WING (and docs/architecture.md)"
    backwards = [imp for imp in imps if imp.source in WING and imp.target in WING
                 and WING.index(imp.target) >= WING.index(imp.source)]
    assert not backwards, f"the wing's modules import only those before them in WING: {backwards}"
    # the wing is loaded when used: the package face and the command line import it inside functions
    eager = [imp for imp in imps if not imp.source.startswith("modaluq.monitoring") and imp.function is None
             and (imp.target == "modaluq.monitoring" or imp.target.startswith("modaluq.monitoring."))]
    assert not eager, f"imports of the monitoring wing at import time: {eager}"


def test_the_rule_itself_catches_an_upward_import_and_a_private_name(tmp_path):
    # the checks above must be able to fail: an upward import at top level, a private helper and
    # an upward import inside a method (a convenience method is no exception)
    src = tmp_path / "modaluq" / "checks.py"
    src.parent.mkdir()
    src.write_text("from .plot import plot_mode_shapes\nfrom .settings import _helper\n\n\n"
                   "class Result:\n    def plot(self):\n        from .analysis import Analysis\n")
    global PACKAGE
    saved, PACKAGE = PACKAGE, tmp_path / "modaluq"
    try:
        imps = imports_of("modaluq.checks", src, {"modaluq.checks", "modaluq.plot", "modaluq.settings",
                                                  "modaluq.analysis"})
    finally:
        PACKAGE = saved
    assert [(i.target, layer_of(i.target) > layer_of(i.source)) for i in imps] == [
        ("modaluq.plot", True), ("modaluq.settings", True), ("modaluq.analysis", True)]
    assert imps[1].names == ["_helper"]
    assert (imps[2].cls, imps[2].function) == ("Result", "plot")


def test_the_core_stubs_name_everything_the_extension_holds():
    # python/modaluq/_core.pyi (scripts/stubs.sh) for type checkers and editors; py.typed marks it
    from modaluq import _core

    stub = ast.parse((PACKAGE / "_core.pyi").read_text(encoding="utf-8"))
    in_stub = {n.name for n in stub.body if isinstance(n, (ast.ClassDef, ast.FunctionDef))}
    in_stub |= {t.id for n in stub.body if isinstance(n, (ast.Assign, ast.AnnAssign))
                for t in (n.targets if isinstance(n, ast.Assign) else [n.target]) if isinstance(t, ast.Name)}
    public = {n for n in dir(_core) if not n.startswith("_")}
    assert public - in_stub == set(), "regenerate the stubs: bash scripts/stubs.sh"
    classes = {n.name: n for n in stub.body if isinstance(n, ast.ClassDef)}
    for name, node in classes.items():
        members = {m.name for m in node.body if isinstance(m, (ast.FunctionDef, ast.ClassDef))} | {
            t.id for m in node.body if isinstance(m, ast.AnnAssign) for t in [m.target] if isinstance(t, ast.Name)}
        real = {m for m in vars(getattr(_core, name)) if not m.startswith("_")}  # its own, not inherited
        assert real - members == set(), f"_core.{name}: regenerate the stubs (bash scripts/stubs.sh)"
    assert (PACKAGE / "py.typed").exists()


def test_documents_cited_in_the_code_exist_with_the_sections_cited():
    # "docs/uq-math.md §5.5" in a comment is a promise: the file and the section must be there
    root = PACKAGE.parents[1]
    cited = set()
    for path in [*root.glob("python/**/*.py"), *root.glob("cpp/include/**/*.hpp"), *root.glob("bindings/*.cpp"),
                 *root.glob("tests/cpp/*.cpp"), *root.glob("tests/python/**/*.py")]:
        for m in re.finditer(r"docs/([A-Za-z0-9_-]+\.md)(?:\s+§\s*([0-9]+(?:\.[0-9]+)*))?", path.read_text("utf-8")):
            cited.add((m.group(1), m.group(2) or "", path.relative_to(root).as_posix()))
    assert cited, "the search finds nothing: the test would pass vacuously"
    missing = []
    for doc, section, where in sorted(cited):
        f = root / "docs" / doc
        if not f.exists():
            missing.append(f"{where}: docs/{doc}")
        elif section and not re.search(rf"^(#+ +|\*\*){re.escape(section)}[ .]", f.read_text("utf-8"), re.M):
            missing.append(f"{where}: docs/{doc} §{section}")
    assert not missing, f"cited but not there: {missing}"
