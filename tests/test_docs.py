"""The project's documents and settings as a newcomer meets them: links that resolve, a short
README, and every env's resolved configuration unchanged by where its defaults live."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SNAPSHOT = Path(__file__).parent / "data" / "resolved_configs.json"


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: p.name)
def test_every_relative_link_resolves(document):
    missing = [
        target
        for target in re.findall(r"\]\(([^)\s]+)\)", document.read_text())
        if not target.startswith(("http://", "https://", "#", "mailto:"))
        and not (document.parent / target.split("#")[0]).exists()
    ]
    assert not missing, f"{document.name}: {missing}"


def test_the_readme_is_short_and_reaches_every_doc():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.encode()) <= 10_000
    assert all(f"docs/{page.name}" in readme for page in DOCUMENTS[1:])
    assert "make run" in readme and "make test" in readme


LIBRARY = sorted([*(ROOT / "hintsjax").rglob("*.py"), *(ROOT / "envs").rglob("*.py")])
# a measurement's date or machine, which belongs in docs/ beside the command that made it
DATED = re.compile(r"\b(H100|H200|A100|RTX ?\d{4}|20\d\d-[01]\d-[0-3]\d)\b")


def test_library_modules_keep_short_docstrings_and_no_dated_measurements():
    """A module's docstring says what it owns and why in at most 15 lines; dates and GPU names
    (which go stale) stay out of hintsjax/ and envs/ (docs/ holds them with their commands)."""
    import ast

    long = {}
    dated = []
    for path in LIBRARY:
        text = path.read_text()
        doc = ast.get_docstring(ast.parse(text), clean=False) or ""
        if len(doc.splitlines()) > 15:
            long[str(path.relative_to(ROOT))] = len(doc.splitlines())
        dated += [
            f"{path.relative_to(ROOT)}:{n}"
            for n, line in enumerate(text.splitlines(), 1)
            if DATED.search(line)
        ]
    assert not long, long
    assert not dated, dated


def test_every_envs_resolved_configuration_matches_the_snapshot():
    """The resolved config of every shipped env x agent, as `python -m hintsjax.run env=E agent=A`
    resolves it, equals the stored snapshot (tests/data/resolved_configs.json). A deliberate change
    of defaults regenerates it (`python tests/test_docs.py`) and says so in its commit."""
    from hintsjax.settings import layers

    snapshot = json.loads(SNAPSHOT.read_text())
    resolved = {
        key: layers.to_dict(layers.run_config(dict(zip(("env", "agent"), key.split("/")))))
        for key in snapshot
    }
    assert json.loads(json.dumps(resolved, sort_keys=True)) == snapshot


def write_snapshot() -> None:
    """Regenerate the snapshot: `python tests/test_docs.py` (after a deliberate change of
    defaults)."""
    from test_cli import SHIPPED_ENVS

    from hintsjax.models.agents import AGENTS
    from hintsjax.settings import layers

    resolved = {
        f"{e}/{a}": layers.to_dict(layers.run_config({"env": e, "agent": a}))
        for e in SHIPPED_ENVS
        for a in AGENTS
    }
    SNAPSHOT.write_text(json.dumps(resolved, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    write_snapshot()


def test_the_design_names_every_module_and_script():
    """docs/design.md's file list keeps up with the code: every module of hintsjax/ and envs/ and
    every script of experiments/ is named there (by its file name)."""
    design = (ROOT / "docs" / "design.md").read_text()
    files = [
        *(ROOT / "hintsjax").rglob("*.py"),
        *(ROOT / "envs").glob("*.py"),
        *(ROOT / "experiments").glob("*.py"),
    ]
    missing = sorted(
        str(f.relative_to(ROOT)) for f in files if f.name != "__init__.py" and f.name not in design
    )
    assert not missing, f"docs/design.md does not name {missing}"


PATH_NAMED = re.compile(
    r"(?<![\w/.-])((?:hintsjax|envs|experiments|tests|benchmarks)/[\w/]+\.py)\b"
)
NAMING = [
    *DOCUMENTS,
    ROOT / "CONTRIBUTING.md",
    *sorted((ROOT / "experiments" / "results").glob("*.md")),
    *sorted(
        p
        for folder in ("hintsjax", "envs", "experiments", "tests")
        for p in (ROOT / folder).rglob("*.py")
    ),
]


MODULE_NAMED = re.compile(r"\bhintsjax(?:\.\w+)+")


def names_something(dotted: str) -> bool:
    """Whether a dotted `hintsjax.<...>` names a module, or a name a module or package defines
    (read from the source, not imported): each package step must be a module, a sub-package or a
    name bound in the package's __init__.py; past a module file the rest is its attribute.
    hintsjax.envs is the envs/ folder (pyproject's package-dir)."""
    parts = dotted.split(".")[1:]
    folder, parts = (ROOT / "envs", parts[1:]) if parts[0] == "envs" else (ROOT / "hintsjax", parts)
    for part in parts:
        if (folder / part).is_dir() and (folder / part / "__init__.py").exists():
            folder = folder / part
        elif (folder / f"{part}.py").exists():
            return True
        else:
            source = (folder / "__init__.py").read_text()
            return (
                re.search(
                    rf"^(?:def |class ){part}\b|^{part} *[:=]|^(?:from \S+ )?import .*\b{part}\b",
                    source,
                    re.M,
                )
                is not None
            )
    return True


def test_every_source_path_a_text_names_exists():
    """A module or script named by its path (or a module by its dotted name) in the docs, the
    results' reports or the code (whose strings write those reports) exists: a move renames it
    everywhere. The results' JSON records are left as written: each names the commit it measured."""
    missing = {
        f"{p.relative_to(ROOT)}: {name}"
        for p in NAMING
        for name in PATH_NAMED.findall(p.read_text())
        if not (ROOT / name).exists()
    }
    missing |= {
        f"{p.relative_to(ROOT)}: {name}"
        for p in NAMING
        for name in MODULE_NAMED.findall(p.read_text())
        if not names_something(name)
    }
    assert not missing, sorted(missing)
