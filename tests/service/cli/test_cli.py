"""The ``quadloc`` CLI: help, maps import/export/list/delete on a database, localize, openapi."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from quadloc.maps.model import content_hash, scene_map_from_dict
from quadloc.service.cli.main import main
from quadloc.service.schemas.examples import EXAMPLE_TRUE_WORLD_FROM_CAMERA, MAP_EXAMPLE
from quadloc.service.settings import hash_api_key
from tests.support.buildings import two_chess_rooms_document
from tests.support.reference_data import CHESS_SCENE_PATH

REPO = Path(__file__).resolve().parents[3]
OPENAPI_PATH = REPO / "docs" / "openapi.json"
CHESS_SCENE = CHESS_SCENE_PATH
EXAMPLE = REPO / "docs" / "examples" / "localize_chess.json"


@pytest.fixture
def db(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    for k in ("QUADLOC_DATABASE_URL", "QUADLOC_API_KEYS", "QUADLOC_DATA_DIR"):
        monkeypatch.delenv(k, raising=False)
    return ["--database-url", f"sqlite:///{tmp_path / 'cli.db'}"]


def test_help_teaches_with_examples(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for command in ("serve", "maps", "localize", "openapi", "hash-key"):
        assert command in out
    assert "quadloc localize --map chess docs/examples/localize_chess.json" in out
    for sub in (["serve"], ["maps"], ["maps", "import"], ["localize"], ["openapi"]):
        with pytest.raises(SystemExit):
            main([*sub, "--help"])
        assert "usage: quadloc" in capsys.readouterr().out


def _help_texts() -> dict[str, str]:
    """The help of ``quadloc`` and of every (sub)command, by command path."""
    import argparse

    from quadloc.service.cli.main import build_parser

    out: dict[str, str] = {}

    def walk(parser: argparse.ArgumentParser, path: str) -> None:
        out[path] = parser.format_help()
        for action in parser._actions:  # argparse keeps its subparsers here
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, f"{path} {name}")

    walk(build_parser(), "quadloc")
    return out


#: A repository path in a help text (a file a reader would pass as written).
REPO_PATH = re.compile(r"(?<![\w/.-])((?:docs|tests|sdk|deploy|bench)/[\w./-]+\.\w+)")


def test_help_lists_every_command_and_names_only_files_that_exist() -> None:
    """Every command of ``COMMANDS`` has a help page and is listed by its parent's help
    (``maps build``, ``maps versions``...); every repository file any help names exists."""
    from quadloc.service.cli.main import COMMANDS

    helps = _help_texts()
    for command in COMMANDS:
        *parent, leaf = command.split()
        assert f"quadloc {command}" in helps, command
        listed = re.search(rf"^\s+{re.escape(leaf)}\s", helps[" ".join(["quadloc", *parent])],
                           re.M)
        assert listed, f"{command} missing from the help of quadloc {' '.join(parent)}"
    named = {m for text in helps.values() for m in REPO_PATH.findall(text)}
    assert "docs/examples/localize_chess.json" in named  # the pattern finds paths
    missing = sorted(path for path in named if not (REPO / path).is_file())
    assert not missing, f"the CLI help names files that do not exist: {missing}"


def test_local_localize_in_a_fresh_process_is_within_budget(tmp_path: Path) -> None:
    """``quadloc localize`` without a server, in a new process on a new database: the kernels
    are compiled / loaded before the frame's budget starts, so the example frame localizes
    (it answered time_budget_exceeded when loading them counted against the 1 s budget)."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if not k.startswith("QUADLOC_")}
    env["QUADLOC_DATA_DIR"] = str(tmp_path)
    out = subprocess.run([sys.executable, "-m", "quadloc.service", "localize", "--map", "chess",
                          str(EXAMPLE), "--json"], env=env, cwd=REPO, capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    answer = json.loads(out.stdout)
    assert answer["localized"], answer
    truth = np.asarray(EXAMPLE_TRUE_WORLD_FROM_CAMERA)
    assert np.linalg.norm(np.asarray(answer["world_from_camera"]["translation_m"])
                          - truth[:3, 3]) < 0.05


def test_maps_import_list_export_delete(db: list[str], tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "office.json"
    src.write_text(json.dumps(MAP_EXAMPLE))
    assert main(["maps", "import", str(src), *db]) == 0
    out = capsys.readouterr().out
    expected_hash = content_hash(scene_map_from_dict(MAP_EXAMPLE, version=1))
    assert f'office-3 version 1 (3 objects) etag "{expected_hash}"' in out
    assert main(["maps", "import", str(src), *db]) == 2
    assert "--update" in capsys.readouterr().err
    assert main(["maps", "import", str(src), "--update", *db]) == 0
    assert "office-3 version 2" in capsys.readouterr().out
    assert main(["maps", "list", "--json", *db]) == 0
    listed = {m["map_id"]: m for m in json.loads(capsys.readouterr().out)}
    assert listed["office-3"]["version"] == 2 and "chess" in listed  # demo map seeded
    assert main(["maps", "export", "office-3", "--version", "1", *db]) == 0
    exported = json.loads(capsys.readouterr().out)
    assert scene_map_from_dict(exported).to_dict() == scene_map_from_dict(MAP_EXAMPLE).to_dict()
    assert main(["maps", "list", *db]) == 0
    assert re.search(r"office-3\s+2\s", capsys.readouterr().out)
    assert main(["maps", "delete", "office-3", *db]) == 0
    assert main(["maps", "export", "office-3", *db]) == 1
    assert "not found" in capsys.readouterr().err


def test_import_errors_name_the_field(db: list[str], tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    bad = json.loads(json.dumps(MAP_EXAMPLE))
    bad["objects"][2]["axes"] = [0.1, 0.0, 0.1]
    src = tmp_path / "bad.json"
    src.write_text(json.dumps(bad))
    assert main(["maps", "import", str(src), *db]) == 2
    assert "objects[2].axes" in capsys.readouterr().err
    src.write_text("{not json")
    assert main(["maps", "import", str(src), *db]) == 2


def test_import_chess_format(db: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    if not CHESS_SCENE.exists():
        pytest.skip(f"reference data not found at {CHESS_SCENE}")
    assert main(["maps", "import", str(CHESS_SCENE), "--chess", "--map-id", "chess2", *db]) == 0
    assert "chess2 version 1 (11 objects)" in capsys.readouterr().out


def test_localize_prints_the_pose(db: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["localize", "--map", "chess", str(EXAMPLE), *db]) == 0
    out = capsys.readouterr().out
    t = re.search(r"translation_m\s+= \[([^\]]+)\]", out)
    assert t, out
    translation = np.array([float(x) for x in t.group(1).split(",")])
    assert np.linalg.norm(translation - np.array(EXAMPLE_TRUE_WORLD_FROM_CAMERA)[:3, 3]) < 0.05
    assert "quaternion_wxyz" in out and "confidence" in out
    assert main(["localize", "--map", "chess", "--json", "--convention", "opengl", str(EXAMPLE),
                 *db]) == 0
    body = json.loads(capsys.readouterr().out)
    assert body["world_from_camera"]["convention"] == "opengl"
    assert main(["localize", "--map", "nope", str(EXAMPLE), *db]) == 1
    # metric "none": the P3P/P2E pose, unrefined, no covariance; a bad metric names the field
    assert main(["localize", "--map", "chess", "--json", "--metric", "none", str(EXAMPLE),
                 *db]) == 0
    body = json.loads(capsys.readouterr().out)
    assert body["metric"] == "none" and body["covariance"] is None
    assert body["pose_source"] == "ransac"
    assert main(["localize", "--map", "chess", "--metric", "nope", str(EXAMPLE), *db]) == 2
    assert "options.metric" in capsys.readouterr().err
    # min_confidence 1: not localized, the verified pose printed as a candidate with its
    # probability; a bad value names the field
    assert main(["localize", "--map", "chess", "--min-confidence", "1", str(EXAMPLE),
                 *db]) == 1
    out = capsys.readouterr().out
    assert "NOT LOCALIZED: low_confidence" in out and "candidate 0: confidence" in out
    assert main(["localize", "--map", "chess", "--json", "--on-ambiguity", "best",
                 str(EXAMPLE), *db]) == 0
    assert json.loads(capsys.readouterr().out)["localized"]
    assert main(["localize", "--map", "chess", "--min-confidence", "2", str(EXAMPLE),
                 *db]) == 2
    assert "options.min_confidence" in capsys.readouterr().err


def test_openapi_check_and_hash_key(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["openapi", "--check", str(OPENAPI_PATH)]) == 0
    assert "up to date" in capsys.readouterr().out
    assert main(["hash-key", "s3cret", "--scopes", "read+write"]) == 0
    assert capsys.readouterr().out.strip() == f"{hash_api_key('s3cret')}:read+write"
    assert main(["hash-key", "k", "--scopes", "root"]) == 2


def test_serve_refuses_public_bind_without_keys(db: list[str],
                                                capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--host", "0.0.0.0", *db]) == 2
    assert "QUADLOC_API_KEYS" in capsys.readouterr().err


def test_image_command_refuses_public_bind_without_keys_in_a_real_process() -> None:
    """The image's CMD (``quadloc serve --host 0.0.0.0``) without keys: exit 2 with a message,
    in a real process with a clean ``QUADLOC_*`` environment (was duplicated in
    tests/e2e/test_dockerfile.py)."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if not k.startswith("QUADLOC_")}
    out = subprocess.run([sys.executable, "-m", "quadloc.service", "serve", "--host", "0.0.0.0",
                          "--port", "1"], env=env, cwd=REPO, capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 2
    assert "QUADLOC_API_KEYS" in out.stderr and "Traceback" not in out.stderr


@pytest.mark.parametrize("content,kind", [("[1, 2]", "array"), ('"x"', "string"),
                                          ("3", "number"), ("null", "null")])
def test_maps_import_of_a_non_object_is_a_clear_error(content: str, kind: str, db: list[str],
                                                      tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "not_a_map.json"
    path.write_text(content)
    for extra in (["--map-id", "X"], ["--chess", "--map-id", "X"], []):
        assert main(["maps", "import", str(path), *extra, *db]) == 2
        err = capsys.readouterr().err
        assert f"must be a JSON object, got a JSON {kind}" in err and str(path) in err


UNREACHABLE = "postgresql://postgres@127.0.0.1:1/none?connect_timeout=2"


@pytest.mark.parametrize("argv", [
    ["maps", "list"], ["maps", "export", "chess"], ["maps", "delete", "chess"],
    ["maps", "import", str(REPO / "docs" / "examples" / "office_map.json")],
    ["localize", "--map", "chess", str(EXAMPLE)],
])
def test_database_down_is_a_message_not_a_traceback(argv: list[str],
                                                    monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    for k in ("QUADLOC_DATABASE_URL", "QUADLOC_API_KEYS"):
        monkeypatch.delenv(k, raising=False)
    assert main([*argv, "--database-url", UNREACHABLE]) == 2
    err = capsys.readouterr().err
    assert err.startswith("quadloc: error: database unreachable") and "--database-url" in err


def test_database_down_in_a_real_process_prints_no_traceback() -> None:
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if not k.startswith("QUADLOC_")}
    out = subprocess.run([sys.executable, "-m", "quadloc.service", "maps", "list", "--database-url",
                          UNREACHABLE], env=env, cwd=REPO, capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr and "database unreachable" in out.stderr


@pytest.mark.parametrize("var,value", [("QUADLOC_API_KEYS", ","),
                                       ("QUADLOC_MAX_DETECTIONS", "300"),
                                       ("QUADLOC_MAX_BATCH_FRAMES", "65")])
def test_invalid_settings_are_a_message(var: str, value: str, db: list[str],
                                        monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv(var, value)
    assert main(["maps", "list", *db]) == 2
    err = capsys.readouterr().err
    assert "invalid settings" in err and var.removeprefix("QUADLOC_").lower() in err


def test_maps_versions_on_the_local_database(db: list[str], tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "office.json"
    src.write_text(json.dumps(MAP_EXAMPLE))
    assert main(["maps", "import", str(src), *db]) == 0
    assert main(["maps", "import", str(src), "--update", "--name", "v2", *db]) == 0
    capsys.readouterr()
    assert main(["maps", "versions", "office-3", *db]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].split() == ["VERSION", "CREATED", "ETAG"]
    assert [line.split()[0] for line in lines[1:]] == ["1", "2"]
    assert main(["maps", "versions", "no-such-map", *db]) == 1
    assert "no-such-map" in capsys.readouterr().err
    # a server URL without a scheme is refused with a message naming the option
    assert main(["--url", "127.0.0.1:8000", "maps", "list"]) == 2
    assert "--url" in capsys.readouterr().err


def _two_rooms_file(tmp_path: Path) -> Path:
    path = tmp_path / "two-rooms.json"
    path.write_text(json.dumps(two_chess_rooms_document("two-rooms")))
    return path


def test_localize_hints_by_zone_or_position(db: list[str], tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """On two exact copies of a room the frame is ambiguous (candidates printed with their
    zones); ``--hint-zone room-b`` or ``--hint-position`` near room-b's copy of the true pose
    (``--hint-sigma`` 2 m) localizes it in room-b, 20 m from the true Chess pose along x; a
    position without sigma, a sigma alone, or both kinds are refused."""
    assert main(["maps", "import", str(_two_rooms_file(tmp_path)), *db]) == 0
    capsys.readouterr()
    truth_b = np.array(EXAMPLE_TRUE_WORLD_FROM_CAMERA)[:3, 3] + [20.0, 0.0, 0.0]
    assert main(["localize", "--map", "two-rooms", str(EXAMPLE), *db]) == 1
    out = capsys.readouterr().out
    assert "NOT LOCALIZED: ambiguous" in out
    assert "zone room-a" in out and "zone room-b" in out
    near_b = [str(v) for v in truth_b + np.array([1.0, -1.0, 0.0])]
    for hint in (["--hint-zone", "room-b"], ["--hint-position", *near_b, "--hint-sigma", "2"]):
        assert main(["localize", "--map", "two-rooms", "--json", *hint, str(EXAMPLE), *db]) == 0
        body = json.loads(capsys.readouterr().out)
        assert body["localized"] and body["zone"] == "room-b", hint
        assert np.linalg.norm(np.array(body["world_from_camera"]["translation_m"])
                              - truth_b) < 0.05
    assert main(["localize", "--map", "two-rooms", "--hint-zone", "attic", str(EXAMPLE),
                 *db]) == 2
    assert "hint.zone_id" in capsys.readouterr().err
    for bad in (["--hint-position", "0", "0", "0"], ["--hint-sigma", "2"]):
        assert main(["localize", "--map", "two-rooms", *bad, str(EXAMPLE), *db]) == 2
        assert "--hint-" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse: the two kinds are mutually exclusive
        main(["localize", "--map", "two-rooms", "--hint-zone", "room-b", "--hint-position",
              "0", "0", "0", "--hint-sigma", "2", str(EXAMPLE), *db])
