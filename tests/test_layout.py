"""The package's shape, read from its source: layers as folders, each importing only its own and
those below it (``LAYERS``, lowest first; imports inside functions included), nothing loose at the
top but the public entry points, no import cycle among its modules (a lazy import still ties the
two modules together), and no function with
more than 8 parameters outside the click command functions (related arguments go in a dataclass
or, for a compiled kernel, a named tuple numba can type)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "fccgrb_cli"
MAX_PARAMETERS = 8

# Lowest first: a package may import its own modules and those of the packages before it.
LAYERS = ("core", "model", "system", "signals", "trial", "solvers", "dynamics", "opensim",
          "anatomy", "plugin_gait", "gait", "pipeline", "results", "batch", "presentation", "view",
          "cli")
# The public entry points, the only modules at the top: above every layer.
TOP = ("fccgrb_cli", "fccgrb_cli.api", "fccgrb_cli.entry")


def _modules(root: Path) -> dict[str, Path]:
    """Dotted module name → file, for every module of the package under ``root``."""
    out = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.with_suffix("").relative_to(root.parent).parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _type_checking(node: ast.AST) -> bool:
    test = getattr(node, "test", None)
    return isinstance(node, ast.If) and (
        (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING")
        or (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"))


def _imports(tree: ast.AST):
    """Every Import / ImportFrom node, anywhere (functions included), except in an
    ``if TYPE_CHECKING:`` block (annotations only: never executed)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if _type_checking(node):
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
        stack.extend(ast.iter_child_nodes(node))


def import_graph(root: Path = PACKAGE) -> dict[str, set[str]]:
    """Module → the package's modules it imports. ``from a.b import c`` counts as an import of
    the module a.b.c when c is one, else of a.b; relative imports are resolved against the
    module's package. The parents a package import runs implicitly are not edges (they are
    every module's, and a package's ``__init__`` would otherwise close a cycle with every
    module below it)."""
    modules = _modules(root)

    def known(name: str) -> str | None:
        return name if name in modules else None

    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        edges = set()
        for node in _imports(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                edges.update(filter(None, (known(a.name) for a in node.names)))
                continue
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, *([node.module] if node.module else [])])
            for alias in node.names:
                target = known(f"{base}.{alias.name}") or known(base)
                if target is not None:
                    edges.add(target)
        edges.discard(name)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), or of one module
    importing itself."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:  # recursion depth ≤ the number of modules
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1 or v in graph[v]:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _is_click_command(node: ast.FunctionDef) -> bool:
    """Decorated with ``@<group>.command(...)`` or ``@click.command(...)``/``group(...)``."""
    for decorator in node.decorator_list:
        call = decorator.func if isinstance(decorator, ast.Call) else decorator
        if isinstance(call, ast.Attribute) and call.attr in ("command", "group"):
            return True
    return False


def _functions(node: ast.AST, prefix: str = ""):
    """(qualified name, FunctionDef) of every function under ``node``, nested ones included."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
            yield f"{prefix}{child.name}", child
            yield from _functions(child, f"{prefix}{child.name}.")
        elif isinstance(child, ast.ClassDef):
            yield from _functions(child, f"{prefix}{child.name}.")
        else:
            yield from _functions(child, prefix)


def parameter_counts(root: Path = PACKAGE) -> dict[str, int]:
    """'module:qualified.name' → its parameter count (positional-only, positional, keyword-only,
    and *args / **kwargs one each; self and cls count), click commands left out."""
    out = {}
    for name, path in _modules(root).items():
        for qualified, node in _functions(ast.parse(path.read_text(), str(path))):
            a = node.args
            if not _is_click_command(node):
                out[f"{name}:{qualified}"] = (
                    len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
                    + (a.vararg is not None) + (a.kwarg is not None))
    return out


def layer_of(module: str, layers: tuple[str, ...] = LAYERS) -> int:
    """The layer a module belongs to: its package's index in ``layers`` (the package's
    ``__init__`` included); the top (len(layers)) for the modules directly in the package."""
    parts = module.split(".")
    return layers.index(parts[1]) if len(parts) > 1 and parts[1] in layers else len(layers)


def upward_imports(graph: dict[str, set[str]], layers: tuple[str, ...] = LAYERS
                   ) -> list[tuple[str, str]]:
    """(importer, imported) for each import of a module in a higher layer than the importer's.
    The package's own ``__init__`` (its version, the lazy public names) is not one: Python runs
    it before any of its modules."""
    return sorted((a, b) for a, edges in graph.items() for b in edges
                  if "." in b and layer_of(b, layers) > layer_of(a, layers))


def test_layers_import_only_downwards():
    assert upward_imports(import_graph()) == []


def test_every_package_is_a_layer_and_nothing_else_is_loose_at_the_top():
    modules = _modules(PACKAGE)
    packages = {name.split(".")[1] for name in modules if name.count(".") >= 2}
    assert packages - set(LAYERS) == set()
    loose = {name for name in modules if name.count(".") == 1 and name not in TOP}
    loose -= {f"fccgrb_cli.{package}" for package in LAYERS}  # the packages' own __init__
    assert loose == set()


def test_no_import_cycle():
    assert cycles(import_graph()) == []


def test_no_function_over_eight_parameters():
    over = {name: n for name, n in parameter_counts().items() if n > MAX_PARAMETERS}
    assert over == {}


# --- the checks themselves, on small packages written here ----------------------------------
def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    root = tmp_path / "pkg"
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def test_a_cycle_through_a_lazy_relative_import_is_found(tmp_path):
    root = _package(tmp_path, {
        "__init__.py": "", "sub/__init__.py": "",
        "a.py": "from pkg.sub import b\n",
        "sub/b.py": "def f():\n    from .c import g\n",
        "sub/c.py": "def g():\n    from .. import a\n",
        "d.py": "import pkg.a\n"})
    assert cycles(import_graph(root)) == [["pkg.a", "pkg.sub.b", "pkg.sub.c"]]


def test_type_checking_imports_and_parent_packages_close_no_cycle(tmp_path):
    root = _package(tmp_path, {
        "__init__.py": "from pkg.a import f\n",
        "a.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.b import B\n"
                "def f():\n    pass\n",
        "b.py": "from pkg.a import f\n"})
    assert cycles(import_graph(root)) == []


def test_an_import_of_a_higher_layer_is_found_lazy_or_not(tmp_path):
    root = _package(tmp_path, {
        "__init__.py": "", "low/__init__.py": "", "high/__init__.py": "",
        "low/a.py": "def f():\n    from pkg.high.b import g\n",
        "low/c.py": "import pkg.low.a\n",
        "high/b.py": "from pkg.low import a\ndef g():\n    pass\n"})
    assert upward_imports(import_graph(root), ("low", "high")) == [("pkg.low.a", "pkg.high.b")]
    assert upward_imports(import_graph(root), ("high", "low")) == [("pkg.high.b", "pkg.low.a")]


def test_parameters_are_counted_as_python_binds_them(tmp_path):
    root = _package(tmp_path, {
        "__init__.py": "",
        "m.py": "import click\n"
                "def f(a, /, b, *c, d, **e):\n    def inner(a, b, c, d, e, f, g, h, i):\n"
                "        pass\n"
                "class K:\n    def method(self, a, b, c, d, e, f, g):\n        pass\n"
                "@main.command()\ndef cmd(a, b, c, d, e, f, g, h, i, j):\n    pass\n"})
    assert parameter_counts(root) == {"pkg.m:f": 5, "pkg.m:f.inner": 9, "pkg.m:K.method": 8}


def test_the_methods_named_at_the_edges_are_the_solvers_own():
    """The command line's and a sweep's method names (``pipeline.options.METHODS``, kept free
    of the solvers' imports for a fast ``--help``) are exactly the solvers' ``Method``s."""
    from fccgrb_cli.pipeline.options import METHODS
    from fccgrb_cli.solvers.methods import METHODS as SOLVED
    from fccgrb_cli.solvers.methods import Method

    assert METHODS == SOLVED
    assert [m.family for m in Method] == ["ad", "nrm", "nrm", *["optimize"] * 4]
    assert [m.value for m in Method if m.drives_angles] == ["ad"]
    assert [m.value for m in Method if m.weighted] == ["nrm-wls"]
    assert Method("cno-ip") == "cno-ip" and str(Method.MO_ED) == "mo-ed"
