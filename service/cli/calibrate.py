"""``quadloc calibrate RECORDING --map ID``: fit and store a map version's own calibration from
the recording it was built from (its ``holdout_every`` frames, app poses as reference): on the
server of ``--url`` / ``QUADLOC_URL`` (``POST /v1/maps/{map_id}/calibration`` through the SDK's
``calibrate_map``), or in this process on the local database (the application's
``calibrations.calibrate``). Prints the NEES and the confidence calibration error before /
after on the held-out frames. Exit status 0 stored, 1 map not found, 2 bad input.
"""

from __future__ import annotations

import argparse
import sys

from quadloc.service.cli.common import CliError, client, local_app, read_json, server_url
from quadloc.service.schemas.calibration import CalibrationOut, CalibrationQualityOut
from quadloc_sdk import Calibration, CalibrationQuality

__all__ = ["cmd_calibrate"]


def _line(name: str, q: CalibrationQualityOut | CalibrationQuality) -> str:
    nees = "-" if q.mean_nees is None else f"{q.mean_nees:.2f}"
    ece = "-" if q.calibration_error is None else f"{q.calibration_error:.3f}"
    if q.calibration_error is not None and q.calibration_error_sd is not None:
        ece += f" +- {q.calibration_error_sd:.3f}"
    floor = "" if q.calibration_error_floor is None \
        else f" (sampling floor {q.calibration_error_floor:.3f})"
    return (f"  {name:<7} mean NEES {nees:>8} ({q.nees_frames} frames within 10 cm)   "
            f"calibration error {ece}{floor}   localized {q.localized}/{q.frames}")


def cmd_calibrate(args: argparse.Namespace) -> int:
    document = read_json(args.file)
    out: CalibrationOut | Calibration
    if server_url(args):
        if args.version is not None and args.version < 1:
            raise CliError("--version: must be >= 1")
        with client(args) as c:
            out = c.calibrate_map(args.map, document, version=args.version)
    else:
        out = local_app(args).calibrations.calibrate(args.map, document, args.version)
    print(f"{out.map_id} version {out.map_version}: calibration stored for {out.key} "
          f"(covariance scale {out.covariance_scale:.4g}, shipped "
          f"{out.shipped_covariance_scale:.4g}; {out.fit_frames} held-out frames)")
    print(_line("before", out.before))
    print(_line("after", out.after))
    if args.json:
        print(out.model_dump_json(indent=2), file=sys.stderr)
    return 0
