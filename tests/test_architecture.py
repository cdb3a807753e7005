"""The packages form a one-way stack: each imports only the layers below it, the shell (``studyapp.cli``) sits on top.

Every module of ``studyapp`` and ``results_analysis`` is parsed with :mod:`ast` (nothing is imported), and every
internal import counts: top-level, inside functions and under ``if TYPE_CHECKING`` alike, because an import hidden
in a function is still a dependency, only one that shows up later, at run time. The layer order below is the
README's architecture table; a new package must be placed in it before it can import anything.
"""
from __future__ import annotations

import ast
import doctest
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOP_PACKAGES = ("studyapp", "results_analysis")

# Lowest first. A package may import packages of strictly lower layers only (not its own layer's neighbours),
# so the graph cannot have a cycle. Same order as the README's architecture table.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("studyapp", "studyapp.errors", "results_analysis"),       # the version, the error type; statistics stand alone
    ("studyapp.resources", "studyapp.durations", "studyapp.tomlfile", "studyapp.safe_io"),   # shipped files, duration rules, TOML, checked binary containers
    ("studyapp.motion", "studyapp.face", "studyapp.audio"),   # the media, each on its own
    ("studyapp.models", "studyapp.demo_content"),             # produce motion from speech (a network, a recipe)
    ("studyapp.render",),                                     # draws media; knows nothing of studies
    ("studyapp.study",),                                      # designs, sessions, storage; no screens
    ("studyapp.ui", "studyapp.web"),                          # the participant's screens: desktop, browser
    ("studyapp.bots",),                                       # scripted participants: drive the session or the UI
    ("studyapp.cli",),                                        # the application shell: commands only
)

# Edges that break the order today, each with the change that removes it. The lead empties this list;
# an entry whose import is gone fails below, so the list cannot go stale.
KNOWN_EXCEPTIONS: dict[tuple[str, str], str] = {}


@dataclass(frozen=True)
class Import:
    source: str   # importing module, dotted
    target: str   # imported module, dotted (internal only)
    where: str    # file:line, relative to the repository
    in_function: bool

    @property
    def edge(self) -> tuple[str, str]:
        return package_of(self.source), package_of(self.target)


def package_of(module: str) -> str:
    """The architecture unit of a module: ``results_analysis`` whole, else ``studyapp.<first part>``.

    >>> package_of("studyapp.render.scene"), package_of("studyapp.errors"), package_of("results_analysis.cli")
    ('studyapp.render', 'studyapp.errors', 'results_analysis')
    """
    parts = module.split(".")
    if parts[0] == "results_analysis":
        return "results_analysis"
    return ".".join(parts[:2])


def _module_name(path: Path, root: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(root).with_suffix("").parts)
    is_package = parts[-1] == "__init__"
    if is_package:
        parts = parts[:-1]
    return ".".join(parts), is_package


def _is_module(root: Path, dotted: str) -> bool:
    path = root.joinpath(*dotted.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def _function_lines(tree: ast.AST) -> set[int]:
    """Line numbers of imports that sit inside a function body (they run only when the function does)."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            lines |= {n.lineno for n in ast.walk(node) if isinstance(n, (ast.Import, ast.ImportFrom))}
    return lines


def collect_imports(root: Path, top_packages: tuple[str, ...] = TOP_PACKAGES) -> list[Import]:
    """Every import of one internal module by another, found in the source under ``root``."""
    found: list[Import] = []
    for top in top_packages:
        for path in sorted((root / top).rglob("*.py")):
            source, is_package = _module_name(path, root)
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            in_function = _function_lines(tree)
            where = f"{path.relative_to(root).as_posix()}:"
            for node in ast.walk(tree):
                if isinstance(node, ast.Import):
                    targets = [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom):
                    if node.level:  # relative: resolve against this module's package
                        base = source.split(".")[: len(source.split(".")) - node.level + (1 if is_package else 0)]
                        module = ".".join(base + ([node.module] if node.module else []))
                    else:
                        module = node.module or ""
                    # `from studyapp import errors` imports the module studyapp.errors, not the root package
                    targets = sorted({f"{module}.{a.name}" if _is_module(root, f"{module}.{a.name}") else module
                                      for a in node.names})
                else:
                    continue
                found += [Import(source, t, where + str(node.lineno), node.lineno in in_function)
                          for t in targets if t.split(".")[0] in top_packages]
    return found


def package_edges(imports: list[Import]) -> dict[tuple[str, str], list[Import]]:
    edges: dict[tuple[str, str], list[Import]] = {}
    for imp in imports:
        a, b = imp.edge
        if a != b:
            edges.setdefault((a, b), []).append(imp)
    return edges


def find_cycle(edges: set[tuple[str, str]]) -> list[str] | None:
    """One cycle of the directed graph as ``[a, b, ..., a]``, or None (depth-first search, three colours).

    >>> find_cycle({("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")})
    ['a', 'b', 'c', 'a']
    >>> find_cycle({("a", "b"), ("a", "c"), ("b", "c")}) is None
    True
    """
    graph: dict[str, list[str]] = {}
    for a, b in sorted(edges):
        graph.setdefault(a, []).append(b)
    state: dict[str, int] = {}   # absent: unseen, 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in graph.get(node, []):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def layer_violations(edges: dict[tuple[str, str], list[Import]],
                     layers: tuple[tuple[str, ...], ...] = LAYERS) -> list[str]:
    """One line per import that does not go strictly down the layer order (or names an undeclared package)."""
    level = {pkg: i for i, layer in enumerate(layers) for pkg in layer}
    out = []
    for (a, b), imports in sorted(edges.items()):
        if a not in level or b not in level:
            problem = f"{a if a not in level else b} is not in LAYERS"
        elif level[b] >= level[a]:
            problem = f"{a} (layer {level[a]}) must not import {b} (layer {level[b]})"
        else:
            continue
        out += [f"{imp.where}: imports {imp.target}: {problem}" for imp in imports]
    return out


@pytest.fixture(scope="module")
def imports() -> list[Import]:
    found = collect_imports(ROOT)
    assert len(found) > 100, "the collector found almost no imports: it is not reading the packages"
    return found


@pytest.fixture(scope="module")
def edges(imports: list[Import]) -> dict[tuple[str, str], list[Import]]:
    return {e: v for e, v in package_edges(imports).items() if e not in KNOWN_EXCEPTIONS}


def test_every_package_has_a_layer() -> None:
    declared = {pkg for layer in LAYERS for pkg in layer}
    on_disk = {"results_analysis", "studyapp"}
    on_disk |= {f"studyapp.{p.stem if p.suffix == '.py' else p.name}" for p in (ROOT / "studyapp").iterdir()
                if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").exists()}
    assert on_disk - declared == set(), "place these packages in LAYERS (and the README's table)"
    assert declared - on_disk == set(), "LAYERS names packages that no longer exist"


def test_package_graph_has_no_cycle(edges: dict[tuple[str, str], list[Import]]) -> None:
    cycle = find_cycle(set(edges))
    if cycle:
        lines = [f"{imp.where}: imports {imp.target}" for a, b in zip(cycle, cycle[1:]) for imp in edges[(a, b)]]
        pytest.fail("import cycle " + " -> ".join(cycle) + "\n" + "\n".join(lines))


def test_imports_follow_the_layer_order(edges: dict[tuple[str, str], list[Import]]) -> None:
    bad = layer_violations(edges)
    assert not bad, "imports against the layer order:\n" + "\n".join(bad)


def test_only_the_shell_imports_the_shell(imports: list[Import]) -> None:
    bad = [f"{i.where}: imports {i.target}" for i in imports
           if package_of(i.target) == "studyapp.cli" and package_of(i.source) != "studyapp.cli"]
    assert not bad, "only studyapp.cli may import studyapp.cli:\n" + "\n".join(bad)


def test_results_analysis_stands_alone(imports: list[Import]) -> None:
    bad = [f"{i.where}: imports {i.target}" for i in imports
           if i.source.startswith("results_analysis") and i.target.split(".")[0] == "studyapp"]
    assert not bad, "results_analysis reads exported results only, never studyapp:\n" + "\n".join(bad)


def test_no_module_is_imported_by_name_string() -> None:
    # A command registered as "studyapp.x.cli" hides its edge from this file (and from readers).
    bad = []
    for top in TOP_PACKAGES:
        for path in sorted((ROOT / top).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Call) and (
                        (isinstance(node.func, ast.Attribute) and node.func.attr == "import_module")
                        or (isinstance(node.func, ast.Name) and node.func.id in ("import_module", "__import__"))):
                    bad.append(f"{path.relative_to(ROOT).as_posix()}:{node.lineno}")
    assert not bad, "import modules with plain import statements:\n" + "\n".join(bad)


def test_known_exceptions_still_exist(imports: list[Import]) -> None:
    stale = set(KNOWN_EXCEPTIONS) - set(package_edges(imports))
    assert not stale, f"these edges are gone: remove them from KNOWN_EXCEPTIONS: {sorted(stale)}"


def test_readme_table_states_the_same_layers() -> None:
    # rows like "| 2 | `studyapp/motion` | ..." ; the root package has no folder of its own
    rows = [line.split("|") for line in (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
            if line.startswith("| ") and line.split("|")[1].strip().isdigit()]
    in_readme = {name.strip().strip("`").removesuffix(".py").replace("/", "."): int(row[1])
                 for row in rows for name in row[2].split(",")}
    declared = {pkg: i for i, layer in enumerate(LAYERS) for pkg in layer if pkg != "studyapp"}
    assert in_readme == declared, "README's architecture table and LAYERS disagree"


# The checks above must be able to fail: the helpers' examples, then a small tree with a cycle hidden in a function.

def test_helper_examples_hold() -> None:
    result = doctest.testmod(sys.modules[__name__], verbose=False)
    assert result.attempted >= 3 and result.failed == 0

def test_collector_sees_a_cycle_hidden_in_a_function(tmp_path: Path) -> None:
    pkg = tmp_path / "studyapp"
    for sub in ("render", "study"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "errors.py").write_text("")
    (pkg / "study" / "other.py").write_text("")
    (pkg / "study" / "stimuli.py").write_text("from studyapp.render import scene\nfrom . import other\n")
    (pkg / "render" / "scene.py").write_text(
        "from studyapp import errors\n\n\ndef build():\n    from ..study.stimuli import load\n    return load\n")
    found = collect_imports(tmp_path, ("studyapp",))
    hidden = [i for i in found if i.in_function]
    assert [(i.source, i.target, i.where) for i in hidden] == [
        ("studyapp.render.scene", "studyapp.study.stimuli", "studyapp/render/scene.py:5")]
    assert {(i.source, i.target) for i in found} == {
        ("studyapp.study.stimuli", "studyapp.render.scene"), ("studyapp.study.stimuli", "studyapp.study.other"),
        ("studyapp.render.scene", "studyapp.errors"), ("studyapp.render.scene", "studyapp.study.stimuli")}
    edges = package_edges(found)
    assert find_cycle(set(edges)) in (["studyapp.render", "studyapp.study", "studyapp.render"],
                                      ["studyapp.study", "studyapp.render", "studyapp.study"])
    layers = (("studyapp.errors",), ("studyapp.render",), ("studyapp.study",))
    assert layer_violations(edges, layers) == [
        "studyapp/render/scene.py:5: imports studyapp.study.stimuli: "
        "studyapp.render (layer 1) must not import studyapp.study (layer 2)"]
