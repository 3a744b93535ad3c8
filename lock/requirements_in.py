"""Print the requirements that `make lock` resolves: the dependencies (and the given extras) of
the checkout's own distributions (pyproject.toml, sdk/python/pyproject.toml), minus those
distributions themselves, which are installed from the working tree, never from an index.

Usage: python lock/requirements_in.py EXTRA... > FILE.in   (pip-compile input)
pip-compile cannot resolve a dependency on a sibling directory's distribution by name
(``quadloc-sdk==0.1.0``) from a pyproject.toml input, so the lock is compiled from this list.
"""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PROJECTS = [ROOT / "pyproject.toml", ROOT / "sdk" / "python" / "pyproject.toml"]


def _name(requirement: str) -> str:
    return re.split(r"[\s\[<>=!~;@]", requirement.strip(), maxsplit=1)[0].lower().replace("_", "-")


def main(extras: list[str]) -> int:
    projects = [tomllib.loads(p.read_text())["project"] for p in PROJECTS if p.exists()]
    local = {_name(p["name"]) for p in projects}
    seen: list[str] = []
    for project in projects:
        reqs = list(project.get("dependencies", []))
        for extra in extras:
            reqs += project.get("optional-dependencies", {}).get(extra, [])
        seen += [r for r in reqs if _name(r) not in local and r not in seen]
    print("\n".join(seen))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
