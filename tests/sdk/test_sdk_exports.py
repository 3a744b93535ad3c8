"""What ``import quadloc_sdk`` exports is what docs/sdk.md says it exports.

docs/sdk.md, section "The Python SDK", has a ``text`` block marked ``sdk-exports``: one line per
module, ``quadloc_sdk.<module>: Name, Name, ...``. Its names and ``quadloc_sdk.__all__`` must be
the same set, every name must be importable from the package, and be the very object its module
defines (a re-export, not a copy).
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import quadloc_sdk

DOC = Path(__file__).resolve().parents[2] / "docs" / "sdk.md"
BLOCK = re.compile(r"^<!-- sdk-exports[^\n]*-->\n```text\n(?P<body>.*?)^```", re.M | re.S)


def documented_exports(text: str) -> dict[str, str]:
    """``{name: module}`` from the sdk-exports block of ``text`` (raises if absent or if a name
    is listed twice)."""
    match = BLOCK.search(text)
    assert match is not None, "docs/sdk.md has no sdk-exports block"
    out: dict[str, str] = {}
    for line in match.group("body").splitlines():
        if not line.strip():
            continue
        module, _, names = line.partition(":")
        assert module.startswith("quadloc_sdk."), f"not a module of the SDK: {line!r}"
        for name in (n.strip() for n in names.split(",")):
            assert name, f"empty name in {line!r}"
            assert name not in out, f"{name} listed twice"
            out[name] = module.strip()
    return out


def test_documented_exports_are_the_packages_all() -> None:
    documented = documented_exports(DOC.read_text())
    assert len(quadloc_sdk.__all__) == len(set(quadloc_sdk.__all__)), "duplicates in __all__"
    missing_from_all = sorted(set(documented) - set(quadloc_sdk.__all__))
    undocumented = sorted(set(quadloc_sdk.__all__) - set(documented))
    assert not missing_from_all, f"documented but not in quadloc_sdk.__all__: {missing_from_all}"
    assert not undocumented, f"in quadloc_sdk.__all__ but not in docs/sdk.md: {undocumented}"


def test_every_export_is_its_modules_object() -> None:
    namespace: dict[str, object] = {}
    exec("from quadloc_sdk import *", namespace)  # the star import users write
    for name, module_name in documented_exports(DOC.read_text()).items():
        module = importlib.import_module(module_name)
        assert name in getattr(module, "__all__", ()), f"{name} is not public in {module_name}"
        assert getattr(quadloc_sdk, name) is getattr(module, name), name
        assert namespace[name] is getattr(module, name), name


def test_the_parser_sees_a_mismatch() -> None:
    """The comparison can fail: a list with a name too many, or a name twice, is caught."""
    text = DOC.read_text()
    extra = text.replace("quadloc_sdk.retry: RetryPolicy",
                         "quadloc_sdk.retry: RetryPolicy, parse_retry_after")
    assert set(documented_exports(extra)) - set(quadloc_sdk.__all__) == {"parse_retry_after"}
    twice = text.replace("quadloc_sdk.retry: RetryPolicy", "quadloc_sdk.retry: RetryPolicy, "
                                                           "RetryPolicy")
    try:
        documented_exports(twice)
    except AssertionError as exc:
        assert "twice" in str(exc)
    else:
        raise AssertionError("a name listed twice was not caught")
