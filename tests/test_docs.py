"""Documents generated from or checked against the code (issue 27).

* ``docs/deployment.md``: the settings table is the one generated from ``Settings``.
* ``README.md``: no test count (it went stale with every commit; how to count is stated).
"""

from __future__ import annotations

import re
from pathlib import Path

from quadloc.service.settings import (
    SETTINGS_TABLE_BEGIN,
    SETTINGS_TABLE_END,
    Settings,
    settings_table_markdown,
)

REPO = Path(__file__).resolve().parents[1]


def test_deployment_settings_table_is_generated_from_the_settings():
    """``docs/deployment.md``'s table is ``settings_table_markdown()`` (regenerate:
    ``python -m quadloc.service.settings --update docs/deployment.md``), with a row per
    field."""
    text = (REPO / "docs" / "deployment.md").read_text()
    assert text.count(SETTINGS_TABLE_BEGIN) == 1 and text.count(SETTINGS_TABLE_END) == 1
    committed = text.split(SETTINGS_TABLE_BEGIN, 1)[1].split(SETTINGS_TABLE_END, 1)[0].strip()
    generated = settings_table_markdown()
    assert committed == generated, "regenerate: python -m quadloc.service.settings --update " \
                                   "docs/deployment.md"
    for name in Settings.model_fields:
        assert f"| `QUADLOC_{name.upper()}` |" in generated, name


def test_settings_table_rows():
    """Bounds, defaults and types come from the fields (two fields checked by hand)."""
    rows = {r.split(" | ")[0].strip("| `"): r for r in settings_table_markdown().splitlines()}
    assert rows["QUADLOC_MAX_SESSIONS"] == (
        "| `QUADLOC_MAX_SESSIONS` | integer | `200` | >= 1, <= 100000 | Live tracking sessions "
        "per process; more -> 503 session-capacity (after idle ones expire). |")
    assert rows["QUADLOC_DATABASE_URL"].startswith(
        "| `QUADLOC_DATABASE_URL` | string (optional) | (unset) | - |")


def test_readme_states_no_test_count():
    """Counts of tests went stale with every commit: the README says how to count instead."""
    text = (REPO / "README.md").read_text()
    assert not re.search(r"\b\d+ (?:of \d+ )?tests\b", text), "README.md states a test count"
    assert "--collect-only" in text
