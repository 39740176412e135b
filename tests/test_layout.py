"""The package's import graph has no circle (issue 27, item 3): every module of model/ and optim/ imports only
modules below it, counting the imports inside functions too (an import inside a function closes a circle as
surely as one at the top; it only hides it until the function runs).

The graph is read from the source with ``ast``, not by importing: every ``import`` and ``from ... import``
anywhere in a module (top level, functions, ``TYPE_CHECKING`` blocks), relative and absolute, with the
package's folders mapped to its module names as pyproject.toml maps them (``flexopt.model`` = model/, ...).
``from pkg import name`` is an edge to ``pkg.name`` when that is a module, else to ``pkg``. Not counted: the
implicit import of a module's parent package (every submodule would otherwise form a circle with its
package's ``__init__``) and imports by string (``importlib.import_module``).

Scope: the whole package (model/, optim/, service/ and the root package); service/'s two circles (app <->
routes_shapes, cli <-> cli_diagnose/cli_modes) went with its move into api/, cli/ and jobs/.
"""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Module-name prefixes whose import graph must be free of circles (see the module docstring).
SCOPE = ("flexopt",)


def _modules() -> dict[str, Path]:
    """Every module of the installed package: its dotted name -> its file, from pyproject's package-dir."""
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    dirs = cfg["package-dir"]
    out: dict[str, Path] = {}
    for pkg, folder in sorted(dirs.items(), key=lambda kv: kv[0]):
        base = ROOT / folder
        for f in base.rglob("*.py"):
            rel = f.relative_to(base).with_suffix("").parts
            if any(p.startswith(".") or p == "__pycache__" for p in rel):
                continue
            if rel[-1] == "__init__":
                rel = rel[:-1]
            name = ".".join((pkg, *rel))
            # a folder mapped on its own (flexopt.model.methods = model/methods) wins over its parent's walk
            if name not in out or len(pkg) > len(out[name][0]):
                out[name] = (pkg, f)
    return {name: f for name, (_, f) in out.items()}


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """The package modules that module ``name`` (file ``path``) imports anywhere in its source."""
    is_pkg = path.name == "__init__.py"
    package = name if is_pkg else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for a in node.names:
                mod = a.name
                while mod and mod not in known:  # import a.b.c -> the deepest package module named
                    mod = mod.rpartition(".")[0]
                if mod:
                    out.add(mod)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - (node.level - 1)])
                full = f"{base}.{node.module}" if node.module else base
            else:
                full = node.module or ""
            for a in node.names:
                sub = f"{full}.{a.name}"
                if sub in known:
                    out.add(sub)
                elif full in known:
                    out.add(full)
    out.discard(name)
    return out


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    return {name: _imports(name, path, known) for name, path in mods.items()}


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One circle of ``graph`` as a closed path [a, b, ..., a], or None (iterative depth-first search)."""
    state: dict[str, int] = {}  # 1 on the current path, 2 finished
    for start in sorted(graph):
        if state.get(start):
            continue
        path: list[str] = [start]
        stack = [iter(sorted(graph[start]))]
        state[start] = 1
        while stack:
            nxt = next(stack[-1], None)
            if nxt is None:
                state[path.pop()] = 2
                stack.pop()
            elif state.get(nxt) == 1:
                return path[path.index(nxt) :] + [nxt]
            elif not state.get(nxt):
                state[nxt] = 1
                path.append(nxt)
                stack.append(iter(sorted(graph.get(nxt, ()))))
    return None


def _in_scope(name: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in SCOPE)


def test_the_reader_sees_every_kind_of_import(tmp_path: Path) -> None:
    # the graph reader must see imports inside functions, relative and absolute ones, `from pkg import module`
    # (a reader that missed any of them would pass any layout): edges model/ has, and a synthetic module
    g = _graph()
    assert "flexopt.model.statics" in g["flexopt.model.analysis"]  # top level, relative
    assert "flexopt.model.scene" in g["flexopt.model.io"]  # `from . import scene as sc`, inside a function
    assert "flexopt.model.rotations" in g["flexopt.model.methods.taylor"]  # `from ..rotations import`, in functions
    f = tmp_path / "x.py"
    f.write_text(
        "import flexopt.model.scene.sub\n"
        "def g():\n    from flexopt.model import units, Analysis\n    import flexopt.optim as o\n"
    )
    known = {"flexopt.model", "flexopt.model.scene", "flexopt.model.units", "flexopt.optim"}
    assert _imports("flexopt.model.x", f, known) == known


def test_the_cycle_finder_finds_a_circle() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_no_import_circle_in_model_and_optim() -> None:
    g = _graph()
    sub = {m: {d for d in deps if _in_scope(d)} for m, deps in g.items() if _in_scope(m)}
    assert len(sub) > 30, sorted(sub)  # the package was found (model/ and optim/ have about 40 modules)
    cycle = _cycle(sub)
    assert cycle is None, "import circle: " + " -> ".join(cycle or [])
