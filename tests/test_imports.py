"""Imports run one way: the import graph of hintsjax/ and envs/ (envs/ is hintsjax.envs), read from
the source with imports inside functions counted, has no circle, and envs/ imports nothing of the
learner. Between the sub-packages too: each imports only the ones below it in LAYERS (the order
docs/design.md draws), so their graph has no circle either. The graph's own functions are checked
on small made-up packages, one with a circle."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# pyproject.toml's package-dir
PACKAGES = {"hintsjax": ROOT / "hintsjax", "hintsjax.envs": ROOT / "envs"}

# The sub-packages, lowest first: a module may import the modules of its own sub-package and of
# those before it here, never of one after it. "hintsjax" stands for the package's own modules:
# its __init__ and the commands (hintsjax/<command>.py, run as python -m hintsjax.<command>).
LAYERS = (
    "hintsjax.envs",
    "hintsjax.gym",
    "hintsjax.system",
    "hintsjax.models",
    "hintsjax.settings",
    "hintsjax.cli",
    "hintsjax.algorithms",
    "hintsjax.evaluation",
    "hintsjax.training",
    "hintsjax.hints",
    "hintsjax",
    "hintsjax.reproduce",
)


def modules(packages: dict[str, Path]) -> dict[str, Path]:
    """Every module of `packages` (dotted package name -> its folder): dotted name -> file. A
    folder mapped to a package of its own (envs/ to hintsjax.envs) is left out of its parent's."""
    found = {}
    for package, folder in packages.items():
        for path in sorted(folder.rglob("*.py")):
            parts = [p for p in path.relative_to(folder).with_suffix("").parts if p != "__init__"]
            name = ".".join([package, *parts])
            if not any(
                other != package
                and other.startswith(package + ".")
                and (name == other or name.startswith(other + "."))
                for other in packages
            ):
                found[name] = path
    return found


def _owner(name: str, known: dict[str, Path]) -> str | None:
    """The module of `known` that a dotted name is, or is inside of (a function's module)."""
    while name and name not in known:
        name = name.rpartition(".")[0]
    return name or None


def import_graph(packages: dict[str, Path]) -> dict[str, set[str]]:
    """module -> the package's modules it imports, anywhere in its source (inside functions and
    `if` blocks too). `from p import x` counts as an import of p.x where that is a module, else
    of p; the parent packages that Python runs first count only where an import names them."""
    known = modules(packages)
    graph: dict[str, set[str]] = {name: set() for name in known}
    for name, path in known.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([base] if base else []))
                targets = [
                    f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base
                    for alias in node.names
                ]
            else:
                continue
            for target in targets:
                owner = _owner(target, known)
                if owner is not None and owner != name:
                    graph[name].add(owner)
    return graph


def layer_of(module: str, layers: tuple[str, ...]) -> str:
    """The entry of `layers` that `module` is, or is inside of (the longest that matches)."""
    return max((p for p in layers if module == p or module.startswith(p + ".")), key=len)


def package_graph(graph: dict[str, set[str]], layers: tuple[str, ...]) -> dict[str, set[str]]:
    """The module graph folded onto `layers`: layer -> the other layers its modules import."""
    folded: dict[str, set[str]] = {layer: set() for layer in layers}
    for module, imported in graph.items():
        folded[layer_of(module, layers)] |= {layer_of(m, layers) for m in imported} - {
            layer_of(module, layers)
        }
    return folded


def upward(graph: dict[str, set[str]], layers: tuple[str, ...]) -> list[str]:
    """The imports of a module from a layer after its own in `layers`, as 'module -> module'."""
    rank = {layer: i for i, layer in enumerate(layers)}
    return sorted(
        f"{m} -> {t}"
        for m, imported in graph.items()
        for t in imported
        if rank[layer_of(t, layers)] > rank[layer_of(m, layers)]
    )


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The groups of modules that import each other in a circle (strongly connected components of
    more than one module, or a module that imports itself), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1 or v in graph.get(v, ()):
                found.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def test_no_module_of_hintsjax_or_envs_is_in_an_import_circle():
    graph = import_graph(PACKAGES)
    assert len(graph) > 40 and graph["hintsjax.run"]  # the whole package was read
    found = circles(graph)
    assert not found, "import circles: " + "; ".join(" <-> ".join(c) for c in found)


def test_the_sub_packages_import_only_those_below_them():
    graph = import_graph(PACKAGES)
    folders = {f"hintsjax.{p.parent.name}" for p in (ROOT / "hintsjax").glob("*/__init__.py")}
    assert folders | {"hintsjax.envs", "hintsjax"} == set(LAYERS), (
        "a sub-package missing from LAYERS, or gone"
    )
    wrong = upward(graph, LAYERS)
    assert not wrong, "imports of a sub-package above the importer's: " + "; ".join(wrong)
    assert not circles(package_graph(graph, LAYERS))


def test_envs_import_nothing_of_the_learner():
    graph = import_graph(PACKAGES)
    learner = {m for m in graph if not m.startswith("hintsjax.envs")}
    wrong = {
        m: sorted(graph[m] & learner)
        for m in graph
        if m.startswith("hintsjax.envs") and graph[m] & learner
    }
    assert not wrong, f"envs/ imports the learner: {wrong}"


def _package(tmp_path: Path, files: dict[str, str]) -> dict[str, Path]:
    for name, text in files.items():
        path = tmp_path / "pkg" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return {"pkg": tmp_path / "pkg"}


def test_a_circle_held_by_an_import_inside_a_function_is_found(tmp_path):
    packages = _package(
        tmp_path,
        {
            "__init__.py": "",
            "settings.py": "def make():\n    from pkg.trainer import train\n    return train\n",
            "trainer.py": "from pkg import settings\nfrom . import leaf\n",
            "leaf.py": "import os\n",
            "sub/__init__.py": "",
            "sub/tool.py": "from ..leaf import *\nimport pkg.sub\n",
        },
    )
    graph = import_graph(packages)
    assert graph == {
        "pkg": set(),
        "pkg.settings": {"pkg.trainer"},
        "pkg.trainer": {"pkg.settings", "pkg.leaf"},
        "pkg.leaf": set(),
        "pkg.sub": set(),
        "pkg.sub.tool": {"pkg.leaf", "pkg.sub"},
    }
    assert circles(graph) == [["pkg.settings", "pkg.trainer"]]


def test_imports_that_run_one_way_make_no_circle(tmp_path):
    packages = _package(
        tmp_path,
        {
            "__init__.py": "",
            "settings.py": "from pkg import leaf\n",
            "trainer.py": "from pkg.settings import make\ndef go():\n    from pkg import leaf\n",
            "leaf.py": "",
        },
    )
    assert circles(import_graph(packages)) == []
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"d"}}) == [["a", "b", "c"], ["d"]]


def test_a_folder_mapped_to_a_subpackage_is_read_once_under_its_own_name(tmp_path):
    (tmp_path / "outer").mkdir()
    (tmp_path / "inner").mkdir()
    (tmp_path / "outer" / "__init__.py").write_text("")
    (tmp_path / "outer" / "top.py").write_text("from outer.inner import core\n")
    (tmp_path / "inner" / "__init__.py").write_text("")
    (tmp_path / "inner" / "core.py").write_text("from outer import top\n")
    graph = import_graph({"outer": tmp_path / "outer", "outer.inner": tmp_path / "inner"})
    assert graph["outer.top"] == {"outer.inner.core"} and graph["outer.inner.core"] == {"outer.top"}
    assert circles(graph) == [["outer.inner.core", "outer.top"]]


def test_a_circle_between_sub_packages_is_found_where_no_module_circle_is(tmp_path):
    packages = _package(
        tmp_path,
        {
            "__init__.py": "",
            "low/__init__.py": "",
            "low/a.py": "",
            "low/b.py": "def late():\n    from pkg.high import c\n",
            "high/__init__.py": "",
            "high/c.py": "",
            "high/d.py": "from pkg.low import a\n",
            "tool.py": "from pkg.high import d\n",
        },
    )
    graph = import_graph(packages)
    layers = ("pkg.low", "pkg.high", "pkg")
    assert circles(graph) == []
    assert package_graph(graph, layers) == {
        "pkg.low": {"pkg.high"},
        "pkg.high": {"pkg.low"},
        "pkg": {"pkg.high"},
    }
    assert circles(package_graph(graph, layers)) == [["pkg.high", "pkg.low"]]
    assert upward(graph, layers) == ["pkg.low.b -> pkg.high.c"]
    assert layer_of("pkg.tool", layers) == "pkg" and layer_of("pkg.high", layers) == "pkg.high"
