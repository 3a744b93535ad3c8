"""Write one benchmark's section of ``docs/results.md`` in place.

Each benchmark owns the block between ``<!-- BEGIN name -->`` and ``<!-- END name -->``; the
block is replaced whole (or appended if absent) under an exclusive file lock, so benchmarks run
in parallel never lose each other's sections.
"""

from __future__ import annotations

import fcntl
import os
import subprocess
from pathlib import Path

RESULTS_PATH = Path(__file__).resolve().parent.parent / "docs" / "results.md"


def update_results_section(name: str, markdown: str, path: Path = RESULTS_PATH) -> None:
    """Replace (or append) the section ``name`` of ``path`` with ``markdown``."""
    begin, end = f"<!-- BEGIN {name} -->", f"<!-- END {name} -->"
    block = f"{begin}\n{markdown.strip()}\n{end}"
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


def tree_version(tree: Path) -> str:
    """``branch at <short commit>`` of a git checkout (worktree; ``HEAD at ...`` when
    detached), else its path: names a compared tree in a results section."""
    try:
        def git(*args: str) -> str:
            return subprocess.run(["git", "-C", str(tree), *args], capture_output=True,
                                  text=True, check=True).stdout.strip()

        return f"{git('rev-parse', '--abbrev-ref', 'HEAD')} at " \
               f"{git('rev-parse', '--short', 'HEAD')}"
    except (OSError, subprocess.CalledProcessError):
        return str(tree)
