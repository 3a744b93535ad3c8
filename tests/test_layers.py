"""The import graph matches the layers of docs/architecture.md, checked on every ``import``
statement of the installed packages (function-level ones included):

* each package imports only the layers below it (:data:`MAY_IMPORT`: within ``quadloc``, the
  prefixes a package's modules may import; the HTTP and CLI front ends call only the
  application layer, the wire models and a few named exceptions);
* no module imports a project module inside a function (such an import hides a cycle or an
  upward arrow), except the CLI front end: it loads its commands by name (``importlib``) and,
  inside a command, the application only where the command runs in this process, so that
  ``--help`` and a command on a server (``--url``) load neither the application nor the solver
  (its function-level imports still follow :data:`MAY_IMPORT` and count in the cycle check);
* no module imports another module's private name (``from x import _y``);
* the graph of modules has no cycle;
* reading the settings or the wire models loads neither gtsam nor OpenCV.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: The repository folder of each installed top-level package.
SOURCES = {"quadloc.factors": REPO / "factors", "quadloc.maps": REPO / "maps",
           "quadloc.service": REPO / "service",
           "quadloc_sdk": REPO / "sdk" / "python" / "quadloc_sdk"}

_SERVICE_BASE = ("quadloc.factors", "quadloc.maps", "quadloc.service.limits",
                 "quadloc.service.settings")
#: package -> the project modules (prefixes) its modules may import (the most specific package
#: of a module applies). Third-party bans are in :data:`NEVER`.
MAY_IMPORT: dict[str, tuple[str, ...]] = {
    "quadloc.factors": ("quadloc.factors",),
    "quadloc.maps": ("quadloc.factors", "quadloc.maps"),
    "quadloc.service": (),
    "quadloc.service.limits": ("quadloc.factors.names",),
    "quadloc.service.settings": ("quadloc.service.limits",),
    "quadloc.service.localization": (*_SERVICE_BASE, "quadloc.service.localization"),
    "quadloc.service.tracking": (*_SERVICE_BASE, "quadloc.service.localization",
                                 "quadloc.service.tracking"),
    # the wire models: light (no solver), the build report is the build's own model
    "quadloc.service.schemas": ("quadloc.factors.names", "quadloc.service.limits",
                                "quadloc.maps.building.report", "quadloc.service.schemas"),
    # the application layer: every use case, over the domain and the wire models
    "quadloc.service.app": (*_SERVICE_BASE, "quadloc.service.localization",
                            "quadloc.service.tracking", "quadloc.service.schemas",
                            "quadloc.service.app", "quadloc_sdk.overlay"),
    # the HTTP front end: the application, the wire models; the map document's schema and
    # errors for the OpenAPI document and the problem handlers
    "quadloc.service.api": ("quadloc.service.app", "quadloc.service.schemas",
                            "quadloc.service.settings", "quadloc.service.limits",
                            "quadloc.service.api", "quadloc.maps.model", "quadloc.maps.errors",
                            "quadloc.maps.store"),
    # the CLI front end: the application, the wire models, the SDK (--url); serve / openapi
    # start or describe the HTTP front end; the map document's validation for its messages
    "quadloc.service.cli": ("quadloc.service.app", "quadloc.service.schemas",
                            "quadloc.service.settings", "quadloc.service.cli",
                            "quadloc.service.api.app", "quadloc.service.api.server",
                            "quadloc.maps.model", "quadloc.maps.errors",
                            "quadloc.maps.building.report", "quadloc.factors.rotations",
                            "quadloc_sdk"),
    "quadloc.service.__main__": ("quadloc.service.cli.main",),
    "quadloc_sdk": ("quadloc_sdk",),
}
#: package -> third-party top-level names it must never import.
NEVER: dict[str, tuple[str, ...]] = {
    "quadloc.factors": ("fastapi", "sqlalchemy", "httpx", "bench", "tests"),
    "quadloc.maps": ("fastapi", "httpx", "bench", "tests"),
    "quadloc.service": ("bench", "tests"),
    "quadloc_sdk": ("gtsam", "fastapi", "sqlalchemy", "bench", "tests"),
}


def _modules() -> Iterator[tuple[str, Path]]:
    """(dotted module name, file) of every module of the installed packages."""
    for package, root in SOURCES.items():
        for path in sorted(root.rglob("*.py")):
            rel = path.relative_to(root).with_suffix("").parts
            if rel[-1] == "__init__":
                rel = rel[:-1]
            yield ".".join((package, *rel)), path


MODULES = dict(_modules())


def _package_of(module: str, table: dict[str, tuple[str, ...]]) -> str | None:
    keys = [k for k in table if module == k or module.startswith(k + ".")]
    return max(keys, key=len) if keys else None


def _hits(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def _resolve(module: str, node: ast.ImportFrom) -> str:
    """The absolute module of a (possibly relative) ``from ... import``."""
    if not node.level:
        return node.module or ""
    base = module.split(".")
    is_package = MODULES[module].name == "__init__.py"
    base = base[: len(base) - node.level + (1 if is_package else 0)]
    return ".".join([*base, *([node.module] if node.module else [])])


def _imports(module: str) -> list[tuple[str, ast.stmt, bool]]:
    """(imported module, statement, inside a function) of every import of ``module``; a
    ``from pkg import sub`` of a submodule counts as importing ``pkg.sub``."""
    tree = ast.parse(MODULES[module].read_text(), filename=str(MODULES[module]))
    out: list[tuple[str, ast.stmt, bool]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            nested = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
            if isinstance(child, ast.Import):
                out.extend((a.name, child, in_function) for a in child.names)
            elif isinstance(child, ast.ImportFrom):
                target = _resolve(module, child)
                for a in child.names:
                    sub = f"{target}.{a.name}"
                    out.append((sub if sub in MODULES else target, child, in_function))
            visit(child, nested)

    visit(tree, False)
    return out


def _project(name: str) -> bool:
    return _hits(name, "quadloc") or _hits(name, "quadloc_sdk")


def test_every_module_imports_only_the_layers_below() -> None:
    bad = []
    for module in MODULES:
        allowed = MAY_IMPORT[_package_of(module, MAY_IMPORT) or module.split(".")[0]]
        never = NEVER.get(_package_of(module, NEVER) or "", ())
        for name, node, _ in _imports(module):
            if _project(name) and not any(_hits(name, a) for a in allowed):
                bad.append(f"{module}:{node.lineno} imports {name}")
            if any(_hits(name, n) for n in never):
                bad.append(f"{module}:{node.lineno} imports {name} (never)")
    assert not bad, "imports against the layers (docs/architecture.md):\n" + "\n".join(bad)


def test_no_project_import_inside_a_function() -> None:
    bad = [f"{module}:{node.lineno} imports {name} inside a function"
           for module in MODULES for name, node, inside in _imports(module)
           if inside and _project(name) and not _hits(module, "quadloc.service.cli")]
    assert not bad, "\n".join(bad)


def test_no_private_name_is_imported_across_modules() -> None:
    bad = []
    for module in MODULES:
        tree = ast.parse(MODULES[module].read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and _project(_resolve(module, node)):
                bad += [f"{module}:{node.lineno} imports {_resolve(module, node)}.{a.name}"
                        for a in node.names if a.name.startswith("_")]
    assert not bad, "\n".join(bad)


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
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
            if len(component) > 1:
                out.append(sorted(component))

    for v in graph:
        if v not in index:
            strong(v)
    return out


def _module_graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for module in MODULES:
        targets = set()
        for name, _, _ in _imports(module):
            # the module itself or the package whose __init__ it imports
            while name and name not in MODULES:
                name = name.rpartition(".")[0]
            if name and name != module:
                targets.add(name)
        graph[module] = targets
    return graph


def test_the_module_graph_has_no_cycle() -> None:
    assert _cycles(_module_graph()) == []


def test_the_checkers_can_fail(tmp_path: Path) -> None:
    """Each check sees a violation when there is one (a checker that cannot fail proves
    nothing)."""
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []
    assert not any(_hits("quadloc.service.api.app", a)
                   for a in MAY_IMPORT["quadloc.service.localization"])
    path = tmp_path / "m.py"
    path.write_text("def f():\n    from quadloc.service.api import app\n")
    MODULES["quadloc.service.localization.fake"] = path
    try:
        found = _imports("quadloc.service.localization.fake")
    finally:
        del MODULES["quadloc.service.localization.fake"]
    assert found[0][0] == "quadloc.service.api.app" and found[0][2] is True


@pytest.mark.parametrize("module", ["quadloc.service.settings", "quadloc.service.schemas.localize",
                                    "quadloc.service.schemas.sessions",
                                    "quadloc.service.schemas.builds", "quadloc.service.limits"])
def test_reading_settings_loads_neither_gtsam_nor_cv2(module: str) -> None:
    code = (f"import sys, {module}\n"
            "print(','.join(m for m in ('gtsam', 'cv2') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=REPO, check=True, timeout=60).stdout.strip()
    assert out == "", f"import {module} loaded {out}"


def test_the_cli_loads_no_solver_for_help_and_version() -> None:
    """``quadloc --version`` / ``--help`` import neither gtsam, numba, OpenCV nor the
    application (the commands load when they run)."""
    code = ("import sys\nfrom quadloc.service.cli.main import build_parser\n"
            "build_parser().format_help()\n"
            "print(','.join(m for m in ('gtsam', 'numba', 'cv2', 'numpy', "
            "'quadloc.service.app.context') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=REPO, check=True, timeout=60).stdout.strip()
    assert out == "", f"the CLI's parser loaded {out}"


class _NotFoundHandler(BaseHTTPRequestHandler):
    """Every request: 404 with a problem document (what a server says of a missing map)."""

    def _answer(self) -> None:
        self.rfile.read(int(self.headers.get("Content-Length") or 0))
        body = json.dumps({"type": "https://quadloc.dev/problems/map-not-found",
                           "title": "Map not found", "status": 404,
                           "detail": "no map 'nowhere'"}).encode()
        self.send_response(404)
        self.send_header("Content-Type", "application/problem+json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    do_GET = do_POST = do_DELETE = do_PUT = _answer  # noqa: N815 (the base class' names)

    def log_message(self, format: str, *args: object) -> None:
        pass


def test_commands_on_a_server_load_neither_the_application_nor_the_solver() -> None:
    """``quadloc --url URL ...`` works through the SDK: the commands that run on a server import
    neither the application, its database layer, numpy nor the solver (each answers a
    missing map here: exit status 1 or 2, the server's message)."""
    server = ThreadingHTTPServer(("127.0.0.1", 0), _NotFoundHandler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{server.server_address[1]}"
    commands = [["maps", "list"], ["maps", "versions", "nowhere"], ["maps", "export", "nowhere"],
                ["maps", "delete", "nowhere"],
                ["localize", "--map", "nowhere", "docs/examples/localize_chess.json"],
                ["calibrate", "docs/examples/room_recording.json.gz", "--map", "nowhere"],
                ["maps", "build", "docs/examples/room_recording.json.gz", "--map-id", "nowhere"]]
    heavy = ("gtsam", "numba", "cv2", "numpy", "sqlalchemy", "quadloc.service.app",
             "quadloc.maps")
    code = ("import sys\nfrom quadloc.service.cli.main import main\n"
            f"statuses = [main(['--url', {url!r}, *c]) for c in {commands!r}]\n"
            "print(statuses)\n"
            f"print(','.join(m for m in {heavy!r} if m in sys.modules))")
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              cwd=REPO, timeout=120)
    finally:
        server.shutdown()
    assert proc.returncode == 0, proc.stderr[-3000:]
    statuses, loaded = proc.stdout.split("\n")[:2]
    assert all(s in (1, 2) for s in json.loads(statuses)), (statuses, proc.stderr)
    assert proc.stderr.count("no map 'nowhere'") == len(commands), proc.stderr
    assert loaded == "", f"a command on a server loaded {loaded}"
