"""``docs/results.md`` is a record (issue 27): every benchmark section carries the stamp of its
run (command, commit, date: ``bench.results_doc.STAMP_RE``) and no record names a
machine-local path; the stamping itself (``update_results_section``) is exercised on a scratch
document."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from bench.results_doc import (
    MACHINE_LOCAL_PATH_RE,
    SECTION_RE,
    STAMP_RE,
    public_command,
    update_results_section,
)

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "docs" / "results.md"
#: Documents that are records and so may name no machine-local path.
RECORD_DOCS = ("docs/results.md", "docs/CHANGELOG.md")


def _sections(text: str) -> dict[str, str]:
    return {m["name"]: m["body"] for m in SECTION_RE.finditer(text)}


def test_every_results_section_is_stamped():
    """One stamp per section, right under its heading; a commit git knows (the figures' code
    can be checked out), a date not before the commit's own day when the section was re-run
    at that commit."""
    text = RESULTS.read_text()
    sections = _sections(text)
    assert len(sections) >= 10, sorted(sections)
    assert text.count("<!-- BEGIN ") == len(sections), "a BEGIN marker without its END"
    for name, body in sections.items():
        stamps = list(STAMP_RE.finditer(body))
        assert len(stamps) == 1, f"section {name!r}: {len(stamps)} stamp lines"
        lines = body.split("\n")
        assert lines[0].startswith("## "), f"section {name!r} does not open with its heading"
        assert STAMP_RE.fullmatch(lines[2]), f"section {name!r}: stamp not under the heading"
        s = stamps[0]
        assert s["command"].startswith(("python -m ", ".venv/bin/python -m ")), (name, s)
        commit = subprocess.run(["git", "-C", str(REPO), "cat-file", "-t", s["commit"]],
                                capture_output=True, text=True)
        if commit.returncode == 0:  # a shallow clone may not have it
            assert commit.stdout.strip() == "commit", (name, s["commit"])
        if s["since"]:
            assert s["since"] == s["commit"], f"section {name!r}: since != commit"


@pytest.mark.parametrize("doc", RECORD_DOCS)
def test_record_documents_name_no_machine_local_path(doc):
    text = (REPO / doc).read_text()
    hits = [m.group(0) for m in MACHINE_LOCAL_PATH_RE.finditer(text)]
    assert not hits, f"{doc}: {hits}"


def test_machine_local_path_pattern():
    """The pattern of the check above finds what it must and leaves repository paths."""
    for bad in ("--json /tmp/s25/x.json", "--baseline /work/wt/filed", "/root/.cache/x",
                "see ../notes/x.md", "/home/me/q"):
        assert MACHINE_LOCAL_PATH_RE.search(bad), bad
    for good in ("docs/img/x.png", "bench/data/calibration_records.json.gz",
                 "`QUADLOC_DATA_DIR=/data`", "from `/proc`", "deploy/tmp/x", "a/work/b",
                 "docs/../README.md"):
        assert not MACHINE_LOCAL_PATH_RE.search(good), good


def test_update_results_section_stamps_and_scrubs(tmp_path):
    """The writer every benchmark uses: the stamp goes under the heading, the command names no
    machine-local path, a rewrite replaces the section (one stamp), other sections stay."""
    doc = tmp_path / "results.md"
    doc.write_text("# results\n\n<!-- BEGIN other -->\n## Other\n\nx\n<!-- END other -->\n")
    cmd = public_command(["--json", "/tmp/a/b.json", f"--plots={REPO / 'docs' / 'img'}",
                          "--seeds", "1,2"], module="bench.example")
    assert cmd == "python -m bench.example --json PATH --plots=docs/img --seeds 1,2"
    for run in range(2):
        update_results_section("example", f"## Example\n\nrun {run}, baseline /work/wt/x\n",
                               doc, command=cmd)
    sections = _sections(doc.read_text())
    assert set(sections) == {"other", "example"}
    body = sections["example"]
    assert len(STAMP_RE.findall(body)) == 1 and "run 1" in body and "run 0" not in body
    m = STAMP_RE.search(body)
    assert m is not None and m["command"] == cmd
    assert "baseline PATH" in body and not MACHINE_LOCAL_PATH_RE.search(body)
    assert body.split("\n")[:3] == ["## Example", "", m.group(0)]
