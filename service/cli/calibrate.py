"""``quadloc calibrate RECORDING --map ID``: fit and store a map version's own calibration from
the recording it was built from (its ``holdout_every`` frames, app poses as reference), in this
process on the local database (the application's ``calibrations.calibrate``; a server does the
same with ``POST /v1/maps/{map_id}/calibration``). Prints the NEES and the confidence
calibration error before / after on the report frames. Exit status 0 stored, 1 map not found,
2 bad input.
"""

from __future__ import annotations

import argparse
import sys

from quadloc.service.cli.common import CliError, local_app, read_json, server_url
from quadloc.service.schemas.calibration import CalibrationQualityOut

__all__ = ["cmd_calibrate"]


def _line(name: str, q: CalibrationQualityOut) -> str:
    nees = "-" if q.mean_nees is None else f"{q.mean_nees:.2f}"
    ece = "-" if q.calibration_error is None else f"{q.calibration_error:.3f}"
    return (f"  {name:<7} mean NEES {nees:>8} ({q.nees_frames} frames within 10 cm)   "
            f"calibration error {ece}   localized {q.localized}/{q.frames}")


def cmd_calibrate(args: argparse.Namespace) -> int:
    if server_url(args):
        raise CliError("calibrate runs on the local database; on a server use "
                       "POST /v1/maps/{map_id}/calibration (docs/map_building.md)")
    document = read_json(args.file)
    out = local_app(args).calibrations.calibrate(args.map, document, args.version)
    print(f"{out.map_id} version {out.map_version}: calibration stored for {out.key} "
          f"(covariance scale {out.covariance_scale:.4g}, shipped "
          f"{out.shipped_covariance_scale:.4g}; {out.fit_frames} fit frames)")
    print(_line("before", out.before))
    print(_line("after", out.after))
    if args.json:
        print(out.model_dump_json(indent=2), file=sys.stderr)
    return 0
