"""One distinctive import namespace (issue 27): the server wheel installs only the namespace
package ``quadloc`` (``quadloc.factors``, ``quadloc.maps``, ``quadloc.service``, from the
repository's top-level folders ``factors/``, ``maps/``, ``service/``) and the SDK wheel only
``quadloc_sdk``; no generic top-level name (``factors``, ``maps``, ``service``, ``sdk``) reaches a
user's site-packages.

The wheels are built from a copy of the checkout (nothing is written into it) with the venv's
own build backend, and installed with ``--no-deps --no-index`` into an empty virtual
environment (no network needed: the check is what the wheels themselves put there).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def test_every_package_folder_is_listed_in_pyproject() -> None:
    """A folder of Python files missing from ``[tool.setuptools] packages`` would be left out of
    the wheel (the editable install would still find it): the list must match the folders."""
    setuptools = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(setuptools["packages"])
    found = set()
    for name, folder in setuptools["package-dir"].items():
        for source in (REPO / folder).rglob("*.py"):
            rel = source.parent.relative_to(REPO / folder).parts
            found.add(".".join((name, *rel)))
    assert found <= listed, f"folders {sorted(found - listed)} are not listed"
    for name in listed:  # (the others are folders of package data)
        top = next(k for k in setuptools["package-dir"] if name == k or name.startswith(k + "."))
        folder = REPO / setuptools["package-dir"][top] / Path(*name[len(top):].split(".")[1:])
        assert folder.is_dir(), f"pyproject lists {name}, which has no folder {folder}"


def _top_level_names(site: Path) -> set[str]:
    return {p.name.removesuffix(".py") for p in site.iterdir()
            if not p.name.endswith((".dist-info", ".pth")) and p.name != "__pycache__"}


@pytest.mark.parametrize("pyproject", ["pyproject.toml", "sdk/python/pyproject.toml"])
def test_license_is_an_spdx_expression(pyproject: str) -> None:
    """PEP 639, as setuptools >= 77 wants it: ``license`` an SPDX expression string (the TOML
    table form is deprecated), no ``License ::`` classifier, and a backend that knows the
    form; the license files, if any, listed in ``license-files`` and present."""
    document = tomllib.loads((REPO / pyproject).read_text())
    project = document["project"]
    assert isinstance(project["license"], str), "license must be an SPDX string, not a table"
    assert project["license"] == "MIT"
    assert not [c for c in project.get("classifiers", []) if c.startswith("License ::")]
    assert "setuptools>=77" in document["build-system"]["requires"]
    for pattern in project.get("license-files", []):
        assert list((REPO / pyproject).parent.glob(pattern)), f"{pattern}: no such file"


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_wheels_install_only_the_quadloc_names(tmp_path: Path) -> None:
    src = tmp_path / "src"
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(
        ".git", ".venv*", "build", "*.egg-info", "__pycache__", "var", "node_modules", "docs",
        "tests", "bench", ".pytest_cache", ".ruff_cache", ".mypy_cache"))
    wheels = tmp_path / "wheels"
    for project in (src / "sdk" / "python", src):
        built = subprocess.run(
            [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
             "--disable-pip-version-check", "-q", "-w", str(wheels), str(project)],
            capture_output=True, text=True, timeout=180)
        assert built.returncode == 0, built.stdout[-2000:] + built.stderr[-2000:]
    files = sorted(wheels.glob("*.whl"))
    assert [f.name.split("-")[0] for f in files] == ["quadloc", "quadloc_sdk"]
    for wheel in files:  # the metadata of PEP 639, not the deprecated License field
        with zipfile.ZipFile(wheel) as z:
            metadata = z.read(next(n for n in z.namelist()
                                   if n.endswith(".dist-info/METADATA"))).decode()
        assert "License-Expression: MIT" in metadata.splitlines(), wheel.name
        assert not any(line.startswith("License:") for line in metadata.splitlines())

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=60)
    py = venv / "bin" / "python"
    site = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()"
                                "['purelib'])"], capture_output=True, text=True,
                               check=True).stdout.strip())
    before = _top_level_names(site)
    install = subprocess.run([str(py), "-m", "pip", "install", "--no-deps", "--no-index",
                              "--disable-pip-version-check", "-q", *map(str, files)],
                             capture_output=True, text=True, timeout=120)
    assert install.returncode == 0, install.stderr[-2000:]
    added = _top_level_names(site) - before
    assert added == {"quadloc", "quadloc_sdk"}, added
    assert not (site / "quadloc" / "__init__.py").exists(), "quadloc must be a namespace package"
    assert {p.name for p in (site / "quadloc").iterdir()} >= {"factors", "maps", "service"}
    # the data the service needs at run time is in the wheel
    assert (site / "quadloc" / "maps" / "data" / "chess.json").is_file()
    assert (site / "quadloc" / "maps" / "migrations" / "versions").is_dir()
    assert (site / "quadloc" / "service" / "api" / "static" / "inspector").is_dir()
    # the console script points into the namespace
    script = (venv / "bin" / "quadloc").read_text()
    assert "from quadloc.service.cli.main import main" in script
