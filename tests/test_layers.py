"""The import graph matches the layers of docs/architecture.md.

``quadloc.factors`` (math, metrics, GTSAM factors) <- ``quadloc.maps`` <-
``quadloc.service.localization`` <- ``quadloc.service.api``; ``quadloc_sdk`` stands alone (neither
gtsam nor the server). Checked statically on every ``import`` statement (function-level ones
included), plus two run-time checks that reading the settings or the wire schemas loads neither
gtsam nor OpenCV.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: package (path prefix, dotted) -> top-level names it must never import.
FORBIDDEN: dict[str, tuple[str, ...]] = {
    "quadloc.factors": ("quadloc.maps", "quadloc.service", "bench", "tests", "quadloc_sdk",
                        "fastapi", "sqlalchemy"),
    "quadloc.maps": ("quadloc.service", "bench", "tests", "fastapi"),
    "quadloc.service": ("bench", "tests"),
    "quadloc.service.localization": ("quadloc.service.api", "quadloc.service.tracking",
                                     "quadloc.service.cli"),
    "quadloc_sdk": ("gtsam", "quadloc", "bench", "tests"),
}
#: where each installed package's sources live in the repository
SOURCES = {"quadloc": REPO, "quadloc_sdk": REPO / "sdk" / "python" / "quadloc_sdk"}


def _modules(package: str) -> list[Path]:
    top, *rest = package.split(".")
    root = SOURCES[top].joinpath(*rest)
    return sorted(p for p in root.rglob("*.py") if ".venv" not in p.parts)


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return names


def _hits(name: str, banned: str) -> bool:
    return name == banned or name.startswith(banned + ".")


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_import_graph_follows_the_layers(package: str) -> None:
    files = _modules(package)
    assert files, f"no module found for {package}"
    bad = [f"{path.relative_to(REPO)} imports {name}"
           for path in files for name in sorted(_imports(path))
           for banned in FORBIDDEN[package] if _hits(name, banned)]
    assert not bad, "imports against the layers (docs/architecture.md):\n" + "\n".join(bad)


def test_the_checker_sees_a_violation(tmp_path: Path) -> None:
    """The static check would fail on a wrong arrow (guards against a checker that cannot fail)."""
    path = tmp_path / "m.py"
    path.write_text("def f():\n    from quadloc.service.api import app\n")
    assert any(_hits(n, "quadloc.service") for n in _imports(path))


@pytest.mark.parametrize("module", ["quadloc.service.settings", "quadloc.service.schemas",
                                    "quadloc.service.limits"])
def test_reading_settings_loads_neither_gtsam_nor_cv2(module: str) -> None:
    code = (f"import sys, {module}\n"
            "print(','.join(m for m in ('gtsam', 'cv2') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=REPO, check=True, timeout=60).stdout.strip()
    assert out == "", f"import {module} loaded {out}"
