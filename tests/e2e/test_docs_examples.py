"""Every fenced ``python`` and ``bash`` block of README.md and docs/*.md runs as written, twice
in a row, against a real server (the ``live_server`` fixture, and a second one for the pages
that run beside the others, stand in for ``make serve`` at http://127.0.0.1:8000; the URL is
rewritten to the port). A second run that conflicts with the first (an id created and never
cleaned up, 409) fails the test.

A block that cannot run here says why in a comment right above it,
``<!-- not run: <reason> -->`` (Docker engine, the setup commands themselves); those are listed
and must give a reason. ``<!-- expect: TEXT -->`` above a block: its output must contain TEXT.
Bash blocks of one page share one shell (a variable set in one block is used by the next, as a
reader typing them would); python blocks run each in a fresh interpreter from the repository
root with the venv's ``python`` and ``quadloc`` first on PATH.

The SDK quick starts run too, where their toolchains are installed (else skipped, saying why):
``typescript`` blocks are compiled by tsc against the built package (types checked; the
``@quadloc/client`` import resolves to sdk/typescript itself) and run with node, ``csharp``
blocks (each a program with ``Main``) are compiled by Mono's mcs against the built
QuadLoc.Client.dll and run with mono; both from the repository root, once.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.conftest import run_live_server

REPO = Path(__file__).resolve().parents[2]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
DOC_BASE = "http://127.0.0.1:8000"
FENCE = re.compile(r"^(?:<!-- (?P<marker>[^\n]*?) -->\n)?```(?P<lang>[A-Za-z]*)\n"
                   r"(?P<code>.*?)^```[ \t]*$", re.M | re.S)
#: Commands a docs test must never run on a shared machine (they start containers, publish
#: ports, install packages into the venv, or run the whole suite); blocks using them must be
#: marked ``not run``.
NEVER_RUN = re.compile(r"^\s*(docker|make|podman|kubectl|pip|pip3|apt-get)\b|-m pip\b", re.M)


@dataclass(frozen=True)
class Block:
    doc: Path
    line: int
    lang: str
    code: str
    marker: str

    @property
    def where(self) -> str:
        return f"{self.doc.relative_to(REPO)}:{self.line}"

    @property
    def skip_reason(self) -> str | None:
        m = re.match(r"not run:\s*(.*)", self.marker)
        return m.group(1).strip() if m else None

    @property
    def expect(self) -> str | None:
        m = re.match(r"expect:\s*(.*)", self.marker)
        return m.group(1).strip() if m else None


def blocks(doc: Path) -> list[Block]:
    text = doc.read_text()
    return [Block(doc, text.count("\n", 0, m.start("lang")) + 1, m.group("lang"), m.group("code"),
                  (m.group("marker") or "").strip()) for m in FENCE.finditer(text)]


def runnable(doc: Path) -> list[Block]:
    out = [b for b in blocks(doc) if b.lang in ("python", "bash") and b.skip_reason is None]
    unsafe = [b.where for b in out if NEVER_RUN.search(b.code)]
    if unsafe:  # fail before running anything
        raise AssertionError(f"blocks running docker/make/pip/... must be 'not run': {unsafe}")
    return out


def test_every_block_runs_or_says_why_not() -> None:
    for d in DOCS:
        runnable(d)  # raises on an unmarked docker/make block
    skipped = [b for d in DOCS for b in blocks(d)
               if b.lang in ("python", "bash") and b.skip_reason is not None]
    assert all(b.skip_reason for b in skipped), [b.where for b in skipped if not b.skip_reason]
    # a handful, each for a reason a test cannot provide (a Docker engine, make itself), plus
    # the SDKs' build commands and the example server of docs/sdk-typescript.md and
    # docs/sdk-csharp.md, which tests/e2e/conftest.py's fixtures run instead
    assert len(skipped) <= 10, [(b.where, b.skip_reason) for b in skipped]
    n = sum(len(runnable(d)) for d in DOCS)
    assert n >= 30, n
    for d in DOCS:  # python blocks are programs, not signatures or fragments
        for b in runnable(d):
            if b.lang == "python":
                compile(b.code, b.where, "exec")


def _env(tmp: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("QUADLOC_")}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    tmp.mkdir(parents=True, exist_ok=True)
    env["QUADLOC_DATA_DIR"] = str(tmp)  # local CLI commands never touch a real database
    env["PYTHONPATH"] = str(REPO)
    return env


def _run_page(doc: Path, base: str, env: dict[str, str]) -> list[str]:
    """Run one page's blocks in order; returns failure messages."""
    failures = []
    bash = [b for b in runnable(doc) if b.lang == "bash"]
    if bash:
        script = ["set -u -o pipefail"]
        for i, b in enumerate(bash):
            script += [f"echo '@@BLOCK {i}@@'", b.code.replace(DOC_BASE, base),
                       f"echo \"@@RC {i} $?@@\""]
        proc = subprocess.run(["bash", "-c", "\n".join(script)], cwd=REPO, env=env,
                              capture_output=True, text=True, timeout=300)
        outputs = re.split(r"@@BLOCK \d+@@\n", proc.stdout)[1:]
        if len(outputs) != len(bash):
            return [f"{doc.name}: bash stopped early:\n{proc.stdout[-2000:]}\n"
                    f"{proc.stderr[-2000:]}"]
        for b, out in zip(bash, outputs, strict=True):
            rc = re.search(r"@@RC \d+ (\d+)@@", out)
            if rc is None or rc.group(1) != "0":
                failures.append(f"{b.where}: exit {rc.group(1) if rc else '?'}\n{out[-1500:]}"
                                f"\n{proc.stderr[-1500:]}")
            elif b.expect and b.expect.lower() not in out.lower():
                failures.append(f"{b.where}: expected {b.expect!r} in\n{out[-1500:]}")
    for b in (b for b in runnable(doc) if b.lang == "python"):
        proc = subprocess.run([sys.executable, "-c", b.code.replace(DOC_BASE, base)], cwd=REPO,
                              env=env, capture_output=True, text=True, timeout=120)
        if proc.returncode != 0:
            failures.append(f"{b.where}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
        elif b.expect and b.expect.lower() not in proc.stdout.lower():
            failures.append(f"{b.where}: expected {b.expect!r} in\n{proc.stdout[-1500:]}")
    return failures


#: The pages run on a second server and data directory of their own, beside the rest (the
#: longest page: three builds and four calibrations), so that no page shares a map id or a
#: job with a page running at the same time.
OWN_LANE = ("map_building.md",)


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_all_docs_examples_run_twice_in_a_row(live_server: str, tmp_path: Path) -> None:
    """Two lanes at a time, each its own server and ``QUADLOC_DATA_DIR``: the pages of
    :data:`OWN_LANE`, and the rest in order. In each lane every page runs, then every page
    again, on the same server as the first time (a second run that conflicts with the first
    fails)."""
    lanes = [[d for d in DOCS if d.name in OWN_LANE], [d for d in DOCS if d.name not in OWN_LANE]]
    assert all(lanes), [len(lane) for lane in lanes]

    def run_lane(pages: list[Path], base: str, env: dict[str, str]) -> list[str]:
        for attempt in (1, 2):
            failures = [f for d in pages for f in _run_page(d, base, env)]
            if failures:
                return [f"run {attempt}:", *failures]
        return []

    with run_live_server(tmp_path / "second_server") as second, \
            ThreadPoolExecutor(max_workers=2) as pool:
        jobs = [pool.submit(run_lane, pages, base, _env(tmp_path / f"lane{k}"))
                for k, (pages, base) in enumerate(zip(lanes, (second, live_server), strict=True))]
        failures = [f for job in jobs for f in job.result()]
    assert not failures, "\n\n".join(failures)


def test_default_database_is_per_checkout(monkeypatch: pytest.MonkeyPatch) -> None:
    """``make serve`` in a checkout uses ``<checkout>/var`` (ignored by git), not a directory
    shared by every clone."""
    from quadloc.service.settings import Settings

    monkeypatch.delenv("QUADLOC_DATA_DIR", raising=False)
    monkeypatch.delenv("QUADLOC_DATABASE_URL", raising=False)
    assert Path(Settings().data_dir) == REPO / "var"
    assert "/var/" in (REPO / ".gitignore").read_text().splitlines()


def _sdk_blocks(lang: str) -> list[Block]:
    return [b for d in DOCS for b in blocks(d) if b.lang == lang and b.skip_reason is None]


def _check_output(b: Block, proc: subprocess.CompletedProcess[str]) -> str | None:
    if proc.returncode != 0:
        return f"{b.where}: exit {proc.returncode}\n{proc.stdout[-1500:]}\n{proc.stderr[-2000:]}"
    if b.expect and b.expect.lower() not in proc.stdout.lower():
        return f"{b.where}: expected {b.expect!r} in\n{proc.stdout[-1500:]}"
    return None


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_typescript_quick_starts_compile_and_run(live_server: str, ts_package: Path) -> None:
    found = _sdk_blocks("typescript")
    assert len(found) >= 3, [b.where for b in found]
    out = ts_package / "build-docs"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    for i, b in enumerate(found):
        (out / f"block{i}.ts").write_text(f"// {b.where}\n" + b.code.replace(DOC_BASE, live_server))
    (out / "tsconfig.json").write_text(json.dumps({
        "extends": "../tsconfig.json", "include": ["*.ts"],
        "compilerOptions": {"rootDir": ".", "outDir": "js", "types": ["node"],
                            "declaration": False, "sourceMap": False}}))
    tsc = subprocess.run(["node", "node_modules/typescript/bin/tsc", "-p", "build-docs"],
                         cwd=ts_package, capture_output=True, text=True, timeout=180)
    assert tsc.returncode == 0, f"the TypeScript quick starts do not compile:\n{tsc.stdout}"
    failures = []
    for i, b in enumerate(found):
        proc = subprocess.run(["node", str(out / "js" / f"block{i}.js")], cwd=REPO,
                              capture_output=True, text=True, timeout=120,
                              stdin=subprocess.DEVNULL)
        failures.append(_check_output(b, proc))
    assert not any(failures), "\n\n".join(f for f in failures if f)


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_csharp_quick_starts_compile_and_run(live_server: str, csharp_build: Path) -> None:
    found = _sdk_blocks("csharp")
    assert len(found) >= 2, [b.where for b in found]
    failures = []
    for i, b in enumerate(found):
        src, exe = csharp_build / f"docs_block{i}.cs", csharp_build / f"docs_block{i}.exe"
        src.write_text(f"// {b.where}\n" + b.code.replace(DOC_BASE, live_server))
        mcs = subprocess.run(["mcs", "-langversion:7.2", "-r:System.Net.Http.dll",
                              f"-r:{csharp_build / 'QuadLoc.Client.dll'}", f"-out:{exe}", str(src)],
                             capture_output=True, text=True, timeout=120)
        if mcs.returncode != 0:
            failures.append(f"{b.where}: does not compile\n{mcs.stdout}{mcs.stderr}")
            continue
        proc = subprocess.run(["mono", str(exe)], cwd=REPO, capture_output=True, text=True,
                              timeout=120, stdin=subprocess.DEVNULL)
        failures.append(_check_output(b, proc))
    assert not any(failures), "\n\n".join(f for f in failures if f)
