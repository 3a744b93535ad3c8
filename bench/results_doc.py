"""Write one benchmark's section of ``docs/results.md`` in place, stamped with its run.

Each benchmark owns the block between ``<!-- BEGIN name -->`` and ``<!-- END name -->``; the
block is replaced whole (or appended if absent) under an exclusive file lock, so benchmarks run
in parallel never lose each other's sections.

Every section carries one machine-readable stamp line (:data:`STAMP_RE`), written here right
under the section's heading::

    Command: `python -m bench.trust --write-results` · Commit: 71d380b · Date: 2026-11-27

``Command`` is the command line that ran (machine-local paths replaced by ``PATH``:
:func:`public_command`), ``Commit`` the checkout's HEAD when the benchmark started
(``bench.START_COMMIT``; ``+dirty`` when tracked files other than ``docs/`` and
``bench/data/`` differed from it: commit the code first, then run the benchmark, then commit
the figures), ``Date`` the UTC day of the run. A section whose figures
were not re-run carries `` · Not re-run since <commit>`` after the date (its commit and date
are those of its last run). ``tests/test_docs.py`` checks every section has a stamp and no
section names a machine-local path (:data:`MACHINE_LOCAL_PATH_RE`).
"""

from __future__ import annotations

import fcntl
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent.parent
RESULTS_PATH = REPO_ROOT / "docs" / "results.md"

#: The stamp line of a section (see the module docstring).
STAMP_RE = re.compile(
    r"^Command: `(?P<command>[^`]+)` · Commit: (?P<commit>[0-9a-f]{7,40})(?P<dirty>\+dirty)?"
    r" · Date: (?P<date>\d{4}-\d{2}-\d{2})(?: · Not re-run since (?P<since>[0-9a-f]{7,40}))?$",
    re.MULTILINE)
#: A path of one machine (scratch files, checkouts, home directories) that no committed
#: document may name.
MACHINE_LOCAL_PATH_RE = re.compile(
    r"(?<![\w.])(?:/tmp|/work|/root|/home|/Users|/mnt|/var/tmp|/var/folders|/private)/\S*"
    r"|(?<![\w.])\.\./[A-Za-z_][\w-]*/\S*")
#: A section: its name and its text between the markers.
SECTION_RE = re.compile(r"<!-- BEGIN (?P<name>[\w.-]+) -->\n(?P<body>.*?)\n<!-- END (?P=name) -->",
                        re.DOTALL)


def run_commit(tree: Path = REPO_ROOT) -> str:
    """Short commit of ``tree``'s HEAD, ``+dirty`` when tracked files outside ``docs/`` and
    ``bench/data/`` differ from it; ``unknown`` when git cannot tell."""
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(tree), *args], capture_output=True, text=True,
                              check=True).stdout.strip()

    try:
        commit = git("rev-parse", "--short=7", "HEAD")
        dirty = git("status", "--porcelain", "--untracked-files=no", "--", ".",
                    ":(exclude)docs", ":(exclude)bench/data")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return commit + ("+dirty" if dirty else "")


def public_command(argv: list[str] | None = None, module: str | None = None) -> str:
    """``python -m <module> <args>`` of this process (default: ``sys.argv`` and the running
    ``-m`` module), every argument that is a path inside the checkout made relative to it and
    every other absolute path replaced by ``PATH``: a command that names no machine."""
    if argv is None:
        argv = sys.argv[1:]
    if module is None:
        main = sys.modules.get("__main__")
        spec = getattr(main, "__spec__", None)
        module = spec.name if spec is not None else Path(sys.argv[0]).stem
    words = []
    for arg in argv:
        flag, eq, value = arg.partition("=") if arg.startswith("--") else ("", "", arg)
        words.append(flag + eq + _public_path(value))
    return " ".join(["python", "-m", module, *(shlex.quote(w) for w in words)])


def _public_path(value: str) -> str:
    if not value.startswith(("/", "~")):
        return value
    try:
        return Path(value).expanduser().resolve().relative_to(REPO_ROOT).as_posix()
    except ValueError:
        return "PATH"


def stamp(command: str, commit: str | None = None, date: str | None = None) -> str:
    """The stamp line of a run (defaults: the commit when the benchmark started,
    ``bench.START_COMMIT``, and today's UTC date)."""
    if commit is None:
        from bench import START_COMMIT

        commit = START_COMMIT
    date = time.strftime("%Y-%m-%d", time.gmtime()) if date is None else date
    return f"Command: `{command}` · Commit: {commit} · Date: {date}"


def scrub_machine_paths(text: str) -> str:
    """``text`` with every machine-local path (:data:`MACHINE_LOCAL_PATH_RE`) replaced by
    ``PATH``."""
    return MACHINE_LOCAL_PATH_RE.sub("PATH", text)


def update_results_section(name: str, markdown: str, path: Path = RESULTS_PATH, *,
                           command: str | None = None) -> None:
    """Replace (or append) the section ``name`` of ``path`` with ``markdown``, stamped (module
    docstring) right under its first heading line; ``command``: default
    :func:`public_command` of this process. Machine-local paths in ``markdown`` are replaced
    by ``PATH`` (with a warning on stderr: the benchmark should not print them)."""
    clean = scrub_machine_paths(markdown.strip())
    if clean != markdown.strip():
        print(f"results section {name!r}: machine-local paths replaced by PATH",
              file=sys.stderr)
    line = stamp(public_command() if command is None else scrub_machine_paths(command))
    lines = clean.split("\n")
    at = next((i + 1 for i, s in enumerate(lines) if s.startswith("#")), 0)
    head, rest = lines[:at], lines[at:]
    while rest and not rest[0].strip():
        rest.pop(0)
    lines = head + ([""] if head else []) + [line] + (["", *rest] if rest else [])
    begin, end = f"<!-- BEGIN {name} -->", f"<!-- END {name} -->"
    block = f"{begin}\n" + "\n".join(lines).strip() + f"\n{end}"
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        text = path.read_text() if path.exists() else "# QuadLoc results\n"
        if begin in text and end in text:
            head, rest = text.split(begin, 1)
            _, tail = rest.split(end, 1)
            text = head + block + tail
        else:
            text = text.rstrip("\n") + "\n\n" + block + "\n"
        tmp = path.with_suffix(".tmp")
        tmp.write_text(text)
        os.replace(tmp, path)


def tree_python(tree: Path) -> str:
    """The interpreter that imports ``tree``'s QuadLoc: its own ``.venv`` (``make install``
    there), this interpreter for this checkout. ``PYTHONPATH=tree`` alone does not do it: a
    venv's editable install maps the ``quadloc`` namespace to the checkout it was made in."""
    if tree.resolve() == REPO_ROOT:
        return sys.executable
    python = tree / ".venv" / "bin" / "python"
    if not python.is_file():
        raise SystemExit(f"{tree} has no .venv: run `make install` in it first")
    return str(python)


def tree_version(tree: Path) -> str:
    """``branch at <short commit>`` of a git checkout (worktree; ``HEAD at ...`` when
    detached), else ``a tree outside git``: names a compared tree in a results section
    without its machine-local path."""
    try:
        def git(*args: str) -> str:
            return subprocess.run(["git", "-C", str(tree), *args], capture_output=True,
                                  text=True, check=True).stdout.strip()

        return f"{git('rev-parse', '--abbrev-ref', 'HEAD')} at " \
               f"{git('rev-parse', '--short', 'HEAD')}"
    except (OSError, subprocess.CalledProcessError):
        return "a tree outside git"
