"""One contract: docs/openapi.json is the single source of the wire models of the TypeScript
and C# SDKs. Both generated files record the sha256 of the document they were made from, and
the C# generator (plain Python) is re-run here: when the document changes, these tests fail
naming the command that regenerates the models. (With node present,
tests/e2e/test_sdk_typescript.py also re-runs openapi-typescript and compares the whole file.)"""

from __future__ import annotations

import hashlib
import importlib.util
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SPEC = REPO / "docs" / "openapi.json"
TS_GENERATED = REPO / "sdk" / "typescript" / "src" / "generated" / "openapi.ts"
CS_GENERATED = REPO / "sdk" / "csharp" / "QuadLoc.Client" / "Models.g.cs"


def _recorded_sha256(path: Path) -> str:
    m = re.search(r"^// openapi-sha256: ([0-9a-f]{64})$", path.read_text(), re.M)
    assert m, f"{path.relative_to(REPO)} has no openapi-sha256 header"
    return m.group(1)


def test_typescript_models_were_generated_from_this_openapi_json() -> None:
    assert _recorded_sha256(TS_GENERATED) == hashlib.sha256(SPEC.read_bytes()).hexdigest(), (
        "docs/openapi.json changed since the TypeScript wire types were generated: run "
        "`npm run generate` in sdk/typescript (npm ci first; `make sdk-models` regenerates "
        "both SDKs' models) and commit "
        "sdk/typescript/src/generated/openapi.ts")


def test_csharp_models_are_what_the_generator_makes_of_this_openapi_json() -> None:
    spec = importlib.util.spec_from_file_location(
        "csharp_generate_models", REPO / "sdk" / "csharp" / "generate_models.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert CS_GENERATED.read_text() == module.render(), (
        "docs/openapi.json changed since the C# wire models were generated: run "
        "`python3 sdk/csharp/generate_models.py` (or `make sdk-models`) and commit "
        "sdk/csharp/QuadLoc.Client/Models.g.cs")


def test_every_schema_has_a_model_in_both_languages() -> None:
    import json

    schemas = json.loads(SPEC.read_text())["components"]["schemas"]
    ts, cs = TS_GENERATED.read_text(), CS_GENERATED.read_text()
    for name in schemas:
        assert re.search(rf"^        {re.escape(name)}: {{", ts, re.M), f"TypeScript lacks {name}"
        assert f"public sealed partial class {name}\n" in cs, f"C# lacks {name}"
