"""The house's rules that a machine can check (../shared/DESIGN.md): the arrows between the
engine's packages, no import cycle (imports inside functions included), the kernels at the
bottom, and no function with more than 12 parameters outside numba kernels."""

from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# the engine's packages and what each may import (besides engine.errors and engine.jit)
ALLOWED = {
    "engine.body": set(),
    "engine.pattern": {"engine.body"},
    "engine.collide": {"engine.body"},
    "engine.cloth": {"engine.collide"},  # (engine.collide.base: the Collider interface only)
    "engine.garment": {"engine.body", "engine.pattern"},
    "engine.io": {"engine.body", "engine.collide"},
    "engine.scene": {"engine.body", "engine.pattern", "engine.garment", "engine.cloth", "engine.collide", "engine.io"},
}
BASE = {"engine.errors", "engine.jit", "engine.settings"}


@lru_cache(maxsize=None)
def _modules(top: str) -> dict[str, tuple[Path, ast.AST]]:
    out = {}
    for p in (ROOT / top).rglob("*.py"):
        parts = p.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = (p, ast.parse(p.read_text(encoding="utf-8")))
    return out


def _imports(tree: ast.AST, known) -> set[str]:
    """The project modules a module imports anywhere in it (functions included)."""
    out = set()
    for n in ast.walk(tree):
        names = []
        if isinstance(n, ast.ImportFrom) and n.module and n.level == 0:
            names = [n.module] + [f"{n.module}.{a.name}" for a in n.names]
        elif isinstance(n, ast.Import):
            names = [a.name for a in n.names]
        out |= {m for m in names if m in known}
    return out


def _package(m: str) -> str:
    return ".".join(m.split(".")[:2])


def test_the_engine_packages_import_along_the_arrows():
    mods = _modules("engine")
    wrong = []
    for m, (_, tree) in mods.items():
        pkg = _package(m)
        for d in _imports(tree, set(mods)):
            dp = _package(d)
            if dp == pkg or d in BASE or pkg not in ALLOWED:
                continue
            if dp not in ALLOWED[pkg]:
                wrong.append(f"{m} imports {d}")
    assert not wrong, wrong
    # the cloth solver sees the body only through the Collider interface
    cloth_to_collide = {d for m, (_, t) in mods.items() if m.startswith("engine.cloth")
                        for d in _imports(t, set(mods)) if d.startswith("engine.collide")}
    assert cloth_to_collide <= {"engine.collide.base"}, cloth_to_collide


def test_no_import_cycle():
    mods = {**_modules("engine"), **_modules("app")}
    graph = {m: _imports(t, set(mods)) - {m} for m, (_, t) in mods.items()}
    state: dict[str, int] = {}

    def visit(m, path):
        state[m] = 1
        for d in graph[m]:
            if state.get(d) == 1:
                raise AssertionError(" -> ".join(path[path.index(d):] + [d]) if d in path else f"{m} -> {d}")
            if d not in state:
                visit(d, path + [d])
        state[m] = 2

    for m in graph:
        if m not in state:
            visit(m, [m])


def test_the_engine_imports_nothing_from_the_service():
    for m, (_, tree) in _modules("engine").items():
        assert not any(d.startswith("app") for d in _imports(tree, set(_modules("app")))), m


def test_kernel_files_import_only_numpy_numba_and_kernels():
    for m, (p, tree) in _modules("engine").items():
        if not p.name.startswith("kernels_"):
            continue
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom) and n.module and n.module.startswith("engine"):
                assert n.module == "engine.jit" or n.module.startswith("engine.cloth.kernels_"), (m, n.module)


def _is_numba(fn: ast.FunctionDef) -> bool:
    for d in fn.decorator_list:
        f = d.func if isinstance(d, ast.Call) else d
        if getattr(f, "id", getattr(f, "attr", "")) in ("njit", "serial_kernel", "intrinsic", "overload"):
            return True
    return False


def test_no_function_takes_more_than_twelve_parameters():
    """Numba kernels excepted: each sits behind a small wrapper (engine.cloth.passes, the colliders)."""
    wide = []
    for top in ("engine", "app"):
        for m, (p, tree) in _modules(top).items():
            for fn in ast.walk(tree):
                if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)) and not _is_numba(fn):
                    a = fn.args
                    n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)
                    n -= bool(a.args and a.args[0].arg in ("self", "cls"))
                    if n > 12:
                        wide.append(f"{m}.{fn.name}: {n}")
    assert not wide, wide
