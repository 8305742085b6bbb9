"""The import direction (README "Layout"): ``models`` never imports ``export`` (it evaluates
bundles through the shared ``inference`` module and the runtime), ``runtime`` never imports
``models``, ``export``, ``iil`` or torch, ``data_tools`` none of those, and the
shared torch-free modules (``inference``, ``conformal``, ``bundle``, ``geometry``, ``registry``) import none of
the subpackages. Read from the source (every import statement, lazy ones inside functions too)."""

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "crossing_assist"


def _imports(path: Path, package: str) -> set[str]:
    """Absolute module names imported by ``path`` (relative imports resolved against ``package``)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            out |= {base} | {f"{base}.{a.name}" for a in node.names}
    return out


def _modules(sub: str) -> list[tuple[Path, str]]:
    root = PKG / sub if sub else PKG
    files = sorted(root.rglob("*.py")) if sub else [p for p in PKG.glob("*.py")]
    return [(f, ".".join(["crossing_assist", *f.relative_to(PKG).with_suffix("").parts[:-1]])) for f in files]


@pytest.mark.parametrize("sub, forbidden", [
    # models may use the runtime: crossing-eval --bundle plays frames through it (what the user hears)
    ("models", ("crossing_assist.export", "crossing_assist.iil")),
    ("runtime", ("crossing_assist.models", "crossing_assist.export", "crossing_assist.iil", "torch")),
    ("data_tools", ("crossing_assist.models", "crossing_assist.export", "crossing_assist.runtime", "crossing_assist.iil")),
])
def test_subpackage_imports_point_one_way(sub, forbidden):
    bad = [(f.name, m) for f, pkg in _modules(sub) for m in _imports(f, pkg)
           if any(m == x or m.startswith(x + ".") for x in forbidden)]
    assert not bad, bad


@pytest.mark.parametrize("name", ["inference", "conformal", "bundle", "geometry", "actions", "upms", "registry"])
def test_shared_modules_import_no_subpackage(name):
    path = PKG / f"{name}.py"
    subs = ("crossing_assist.models", "crossing_assist.export", "crossing_assist.runtime", "crossing_assist.iil",
            "crossing_assist.data_tools", "torch")
    bad = [m for m in _imports(path, "crossing_assist") if any(m == s or m.startswith(s + ".") for s in subs)]
    assert not bad, (name, bad)


def test_the_checker_sees_lazy_and_relative_imports(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("def g():\n    from ..export.graph import x\n    import torch\n")
    got = _imports(f, "crossing_assist.models")
    assert "crossing_assist.export.graph" in got and "torch" in got
