"""The shape of the code base (issue 28): kernels/ holds only Warp kernels, functions, structs and constants; the
import graph of wptrack has no cycles (module-level and function-level imports, ``TYPE_CHECKING`` blocks aside); no
library module is over 600 lines without saying why at its top; the README's "How it is built" names every package."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
MAX_LINES = 600
"""A module longer than this says why in its docstring, in a paragraph starting ``Length:``."""


def _modules() -> dict[str, tuple[Path, bool]]:
    out = {}
    for base, prefix in ((REPO / "wptrack", "wptrack"), (REPO / "kernels", "wptrack.kernels")):
        for f in sorted(base.rglob("*.py")):
            rel = f.relative_to(base)
            if base.name == "wptrack" and rel.parts[0] == "kernels":  # a wptrack/kernels link in some checkouts
                continue
            parts = [prefix, *rel.with_suffix("").parts]
            is_pkg = parts[-1] == "__init__"
            out[".".join(parts[:-1] if is_pkg else parts)] = (f, is_pkg)
    return out


def _resolve(module: str | None, level: int, me: str, is_pkg: bool) -> str:
    if level == 0:
        return module or ""
    base = me.split(".") if is_pkg else me.split(".")[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def import_graph() -> dict[str, set[str]]:
    """Module -> the wptrack modules it imports (anywhere in it, ``if TYPE_CHECKING:`` blocks aside; ``from pkg
    import sub`` is an edge to ``pkg.sub``, not to ``pkg``)."""
    mods = _modules()
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for m, (f, is_pkg) in mods.items():
        tree = ast.parse(f.read_text())
        skip = set()
        for n in ast.walk(tree):
            if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.unparse(n.test):
                skip.update(id(x) for x in ast.walk(n))
        for n in ast.walk(tree):
            if id(n) in skip:
                continue
            targets: list[str] = []
            if isinstance(n, ast.Import):
                targets = [a.name for a in n.names]
            elif isinstance(n, ast.ImportFrom):
                base = _resolve(n.module, n.level, m, is_pkg)
                subs = [f"{base}.{a.name}" for a in n.names if f"{base}.{a.name}" in mods]
                targets = subs + ([base] if len(subs) < len(n.names) else [])
            edges[m].update(t for t in targets if t in mods and t != m)
    return edges


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_the_import_graph_has_no_cycles():
    found = cycles(import_graph())
    assert not found, f"import cycles: {found}"


def test_the_cycle_check_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


ALLOWED_KERNEL_IMPORTS = ("__future__", "warp", "functools", "typing", "wptrack.kernels")


@pytest.mark.parametrize("path", sorted((REPO / "kernels").rglob("*.py")), ids=lambda p: str(p.relative_to(REPO)))
def test_kernels_hold_only_warp_code(path):
    """Only @wp.kernel / @wp.func / @wp.struct, constants and kernel factories (``functools.cache`` functions that
    return a kernel); no numpy, cv2 or pyvista."""
    tree = ast.parse(path.read_text())
    for n in tree.body:
        if isinstance(n, (ast.Import, ast.ImportFrom)):
            names = [a.name for a in n.names] if isinstance(n, ast.Import) else [n.module or ""]
            for name in names:
                assert name.startswith(ALLOWED_KERNEL_IMPORTS), f"{path}: imports {name}"
        elif isinstance(n, ast.FunctionDef):
            decorators = [ast.unparse(d) for d in n.decorator_list]
            assert any(d.startswith(("wp.kernel", "wp.func", "functools.cache")) for d in decorators), (
                f"{path}: {n.name} is not a Warp kernel or function"
            )
        elif isinstance(n, ast.ClassDef):
            assert [ast.unparse(d) for d in n.decorator_list] == ["wp.struct"], f"{path}: class {n.name}"
        elif isinstance(n, (ast.Assign, ast.AnnAssign)):
            value = n.value
            ok = value is not None and (
                isinstance(value, ast.Constant) or ast.unparse(value).startswith(("wp.", "(", "int(", "float("))
            )
            assert ok, f"{path}: {ast.unparse(n)[:80]}"


def test_long_modules_say_why():
    long = []
    for f, _ in _modules().values():
        text = f.read_text()
        lines = text.count("\n")
        doc = ast.get_docstring(ast.parse(text)) or ""
        if lines > MAX_LINES and not re.search(r"^Length:", doc, re.M):
            long.append(f"{f.relative_to(REPO)} ({lines} lines)")
    assert not long, f"modules over {MAX_LINES} lines without a 'Length:' paragraph in their docstring: {long}"


def test_readme_names_every_package():
    readme = (REPO / "README.md").read_text()
    section = readme[readme.index("## How it is built") :]
    section = section[: section.find("\n## ", 3) if "\n## " in section[3:] else len(section)]
    inits = [
        p for p in (REPO / "wptrack").rglob("__init__.py") if p.relative_to(REPO / "wptrack").parts[0] != "kernels"
    ]
    inits += list((REPO / "kernels").rglob("__init__.py"))
    packages = sorted(str(p.parent.relative_to(REPO)) + "/" for p in inits)
    missing = [p for p in packages if f"`{p}`" not in section]
    assert not missing, f"README 'How it is built' does not name {missing}"
