"""``quadloc localize --map ID FILE...``: localize the frame of each file (the body of ``POST
/v1/maps/{id}/localize``) on a server (``--url``, through the SDK) or in this process (the
application's localizer, with the server's settings). One answer printed per frame; several
files: a table and a progress bar. Exit status 0 when every frame localized, 1 when one did not.

In process, the numeric kernels are compiled (or loaded from their cache) before the first
frame, so that no frame's time budget pays for it.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from typing import Any

from pydantic import ValidationError

from quadloc.service.cli.common import (
    CliError,
    Progress,
    client,
    format_table,
    local_app,
    read_json,
    server_url,
)
from quadloc.service.schemas.common import field_path
from quadloc.service.schemas.localize import LocalizeRequest, LocalizeResponse

__all__ = ["cmd_localize", "print_answer"]


def print_answer(result: Any) -> None:
    """Human-readable answer (the server's wire model or the SDK's: the same fields)."""
    print(f"map {result.map_id} v{result.map_version}  frame {result.frame_id or '-'}")
    if result.zone is not None:
        print(f"zone {result.zone}")
    if not result.localized:
        print(f"NOT LOCALIZED: {result.reason}")
    else:
        pose = result.world_from_camera
        print(f"world_from_camera ({pose.convention} camera axes):")
        print("  quaternion_wxyz = [" + ", ".join(f"{v:+.6f}" for v in pose.quaternion_wxyz)
              + "]")
        print("  translation_m   = [" + ", ".join(f"{v:+.4f}" for v in pose.translation_m) + "]")
        print(f"confidence {result.confidence:.3f}  inliers {len(result.inliers)}  "
              f"metric {result.metric}  total "
              f"{result.timings_ms.get('total', float('nan')):.1f} ms")
        if result.covariance is not None:
            diag = [max(float(result.covariance.matrix[i][i]), 0.0) for i in range(6)]
            rot = [round(math.degrees(math.sqrt(d)), 3) for d in diag[:3]]
            trans = [round(math.sqrt(d), 4) for d in diag[3:]]
            print(f"std: rotation [deg] {rot}  translation [m] {trans}")
    # the candidate poses of an ambiguous or low-confidence answer, with their probabilities
    for k, a in enumerate(result.alternatives):
        t = " ".join(f"{v:+.3f}" for v in a.world_from_camera.translation_m)
        zone = "" if a.zone is None else f"  zone {a.zone}"
        print(f"candidate {k}: confidence {a.confidence:.3f}  inliers {a.n_inliers}  "
              f"score {a.score:.2f}  translation_m [{t}]{zone}")


def _hint(args: argparse.Namespace) -> dict[str, Any] | None:
    """The hint of ``--hint-zone`` / ``--hint-position`` with ``--hint-sigma`` (None: keep the
    file's); a sigma without a position, or a position without a sigma, is refused."""
    if args.hint_sigma is not None and args.hint_position is None:
        raise CliError("--hint-sigma goes with --hint-position")
    if args.hint_zone is not None:
        return {"zone_id": args.hint_zone}
    if args.hint_position is not None:
        if args.hint_sigma is None:
            raise CliError("--hint-position needs --hint-sigma (its 1-sigma uncertainty, m)")
        return {"position": list(args.hint_position), "sigma_m": args.hint_sigma}
    return None


def _requests(args: argparse.Namespace) -> list[LocalizeRequest]:
    """Every file's request, validated, with the command line's option overrides."""
    overrides = {k: v for k, v in (
        ("metric", args.metric), ("on_ambiguity", args.on_ambiguity),
        ("min_confidence", args.min_confidence)) if v is not None}
    hint = _hint(args)
    requests = []
    for path in args.file:
        body = read_json(path)
        if hint is not None and isinstance(body, dict):
            body["hint"] = hint  # validated with the request below
        if overrides and isinstance(body, dict):
            options = body.setdefault("options", {})
            if isinstance(options, dict):
                options.update(overrides)  # validated with the request below
        try:
            request = LocalizeRequest.model_validate(body)
        except ValidationError as exc:
            raise CliError(f"{path}: invalid request", problems=[
                (field_path(e["loc"]), e["msg"]) for e in exc.errors()]) from exc
        if args.convention:
            request = request.model_copy(update={"options": request.options.model_copy(
                update={"output_convention": args.convention})})
        requests.append(request)
    return requests


def _solver(args: argparse.Namespace) -> tuple[Callable[[LocalizeRequest], Any],
                                               Callable[[], None]]:
    """``(solve, close)``: localize a request through the SDK on the server, or in this
    process against the local database."""
    if server_url(args):
        c = client(args)
        return (lambda request: c.localize(
            args.map, request.model_dump(mode="json", exclude_none=True),
            map_version=args.version)), c.close
    app = local_app(args)
    app.warm_up()  # before any frame's budget starts (module docstring)

    def solve(request: LocalizeRequest) -> LocalizeResponse:
        return app.localizer.localize(args.map, request, args.version)[1]

    return solve, app.close


def cmd_localize(args: argparse.Namespace) -> int:
    requests = _requests(args)
    solve, close = _solver(args)
    progress = Progress(len(requests))
    results = []
    try:
        for i, (path, request) in enumerate(zip(args.file, requests, strict=True)):
            progress.update(i, path)
            results.append(solve(request))
        progress.update(len(requests))
    finally:
        progress.close()
        close()
    if args.json:
        if len(results) == 1:
            print(results[0].model_dump_json(indent=2))
        else:
            print(json.dumps([r.model_dump(mode="json") for r in results], indent=2))
    elif len(results) == 1:
        print_answer(results[0])
    else:
        rows = []
        for path, r in zip(args.file, results, strict=True):
            t = r.world_from_camera.translation_m if r.localized else None
            rows.append([path, "yes" if r.localized else f"no ({r.reason})",
                         f"{r.confidence:.2f}", str(len(r.inliers)),
                         "-" if t is None else " ".join(f"{v:+.3f}" for v in t)])
        print(format_table(["FILE", "LOCALIZED", "CONF", "INLIERS", "TRANSLATION_M"], rows,
                           right=frozenset({2, 3})))
    return 0 if all(r.localized for r in results) else 1
