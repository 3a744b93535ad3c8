"""Sustained localization load on loopback: a real Uvicorn server, asyncio httpx clients.

Run::

    .venv/bin/python -m bench.load [--duration 10] [--concurrency 1 8 32] [--workers 2]
                                   [--frames 48] [--json out.json] [--write-results]

What it does, in one run (so the numbers are comparable on a noisy shared machine):

1. Simulates ``--frames`` frames of the demo Chess map at real ground-truth poses
   (``chess_test_poses.json``, evenly spaced; ``bench.simulate`` default detector noise) and
   builds their ``POST /v1/maps/chess/localize`` bodies.
2. **In process**: calls ``service.localization.pipeline.localize`` on the same frames (same
   options) back to back for ``--duration`` seconds in this process: the per-worker ceiling.
3. Starts ``uvicorn service.api.app:create_app --factory --workers W`` on a free loopback port
   with a temporary SQLite database and the default settings (one solve at a time per process,
   first come first served: the GIL serialises solves anyway).
4. For each concurrency ``c``: ``c`` closed-loop asyncio clients (one keep-alive
   ``httpx.AsyncClient`` connection each) post the frames round-robin for ``--duration``
   seconds (after a short warm-up). Reports requests/s, latency p50/p95/p99 (ms,
   client-measured), errors (transport errors, non-200 answers, or bodies that do not parse),
   and the localized fraction.

HTTP overhead per worker = ``in-process rate / (HTTP rate at concurrency 1)`` - 1: at
concurrency 1 only one request is in flight, so one worker serves it and the difference is the
HTTP path (parsing, validation, serialisation, loopback, client). The client runs on the
same 2 cores as the server, so they also take CPU from it at high concurrency.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
POSES = REPO.parent / "shared" / "data" / "chess_test_poses.json"


def build_frames(n_frames: int, seed: int = 0) -> tuple[list[dict[str, Any]], list[Any]]:
    """``n_frames`` request bodies (and the matching in-process inputs) of simulated frames."""
    from bench.simulate import simulate_frame
    from factors.geometry import Camera, invert_pose, pose_matrix, snap_to_rotation
    from maps.compiled import compile_map
    from maps.demo import load_demo_map
    from service.api.convert import (
        camera_from_request,
        detections_from_request,
        options_from_request,
    )
    from service.api.schemas import LocalizeRequest

    data = json.loads(POSES.read_text())
    camera = Camera.from_matrix(np.array(data["K"]), data["width"], data["height"])
    compiled = compile_map(load_demo_map())
    picks = np.linspace(0, len(data["frames"]) - 1, n_frames).round().astype(int)
    bodies, inputs = [], []
    for k, i in enumerate(picks):
        f = data["frames"][int(i)]
        T = invert_pose(pose_matrix(snap_to_rotation(np.array(f["R"])), f["t"]))
        sim = simulate_frame(compiled, camera, T, seed + k)
        body = {
            "camera": {"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
                       "width": camera.width, "height": camera.height},
            "detections": [{"ellipse": {"cx": d.ellipse.cx, "cy": d.ellipse.cy,
                                        "a": d.ellipse.a, "b": d.ellipse.b,
                                        "angle": d.ellipse.angle},
                            "label": d.label,
                            **({"sigma": d.sigma} if d.sigma is not None else {})}
                           for d in sim.detections],
            "frame_id": f"{f['sequence']}/{f['frame']}",
        }
        req = LocalizeRequest.model_validate(body)
        bodies.append(body)
        inputs.append((detections_from_request(req.detections), compiled,
                       camera_from_request(req.camera), options_from_request(req.options,
                                                                             1000.0)))
    return bodies, inputs


def in_process_rate(inputs: list[Any], duration_s: float) -> dict[str, float]:
    """Back-to-back ``localize()`` calls for ``duration_s``: rate and latency percentiles."""
    from service.localization.pipeline import localize

    for args in inputs[:4]:  # warm caches
        localize(*args)
    lat, localized = [], 0
    t_end = time.perf_counter() + duration_s
    i = 0
    while time.perf_counter() < t_end:
        t0 = time.perf_counter()
        result = localize(*inputs[i % len(inputs)])
        lat.append(time.perf_counter() - t0)
        localized += int(result.localized)
        i += 1
    lat_ms = np.array(lat) * 1e3
    return {"calls": i, "rate_per_s": i / float(np.sum(lat)),
            "p50_ms": float(np.percentile(lat_ms, 50)),
            "p95_ms": float(np.percentile(lat_ms, 95)),
            "p99_ms": float(np.percentile(lat_ms, 99)),
            "localized_fraction": localized / max(i, 1)}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_server(workers: int, data_dir: Path) -> tuple[subprocess.Popen, str]:
    """A real Uvicorn server on a free loopback port; returns (process, base URL)."""
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("QUADLOC_")}
    env.update({"QUADLOC_DATABASE_URL": f"sqlite:///{data_dir / 'load.db'}",
                "QUADLOC_DATA_DIR": str(data_dir), "PYTHONPATH": str(REPO)})
    log = open(data_dir / "uvicorn.log", "wb")  # noqa: SIM115 - lives as long as the server
    proc = subprocess.Popen(
        [sys.executable, "-m", "uvicorn", "service.api.app:create_app", "--factory",
         "--host", "127.0.0.1", "--port", str(port), "--workers", str(workers),
         "--log-level", "warning", "--no-access-log"],
        cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError((data_dir / "uvicorn.log").read_text()[-3000:])
        try:
            if httpx.get(f"{base}/readyz", timeout=2).status_code == 200:
                return proc, base
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    proc.terminate()
    raise RuntimeError("server did not become ready")


def run_level(base: str, bodies: list[dict[str, Any]], concurrency: int, duration_s: float,
              warmup_s: float) -> dict[str, Any]:
    """``concurrency`` closed-loop clients (asyncio tasks sharing one keep-alive
    ``httpx.AsyncClient`` pool, one connection each) posting frames for ``duration_s`` after a
    warm-up. Asyncio rather than threads: the client shares the 2 cores with the server, and
    32 Python threads would spend more CPU fighting over the GIL than sending requests."""
    return asyncio.run(_run_level(base, bodies, concurrency, duration_s, warmup_s))


async def _run_level(base: str, bodies: list[dict[str, Any]], concurrency: int,
                     duration_s: float, warmup_s: float) -> dict[str, Any]:
    url = f"{base}/v1/maps/chess/localize"
    payloads = [json.dumps(b).encode() for b in bodies]
    start = time.perf_counter() + warmup_s
    stop = start + duration_s
    lat: list[float] = []
    pairs: list[tuple[float, float]] = []  # (client latency, server solve time) of OK answers
    errors: dict[str, int] = {}
    localized = 0
    limits = httpx.Limits(max_connections=concurrency, max_keepalive_connections=concurrency)

    async def client_loop(client: httpx.AsyncClient, k: int) -> None:
        nonlocal localized
        i = k
        while True:
            t0 = time.perf_counter()
            if t0 >= stop:
                return
            kind, body = None, None
            try:
                r = await client.post(url, content=payloads[i % len(payloads)],
                                      headers={"content-type": "application/json"})
                if r.status_code == 200:
                    body = r.json()
                else:
                    kind = f"http_{r.status_code}"
            except (httpx.HTTPError, ValueError) as exc:
                kind = type(exc).__name__
            t1 = time.perf_counter()
            i += concurrency
            if t0 < start or t1 > stop:  # warm-up or straddling the end: not counted
                continue
            lat.append(t1 - t0)
            if kind or body is None:
                errors[kind or "no_body"] = errors.get(kind or "no_body", 0) + 1
            else:
                pairs.append((t1 - t0, body["timings_ms"]["total"] / 1e3))
                localized += int(bool(body.get("localized")))

    async with httpx.AsyncClient(timeout=30.0, limits=limits) as client:
        await asyncio.gather(*(client_loop(client, k) for k in range(concurrency)))
    done = len(lat)
    lat_ms = np.array(lat) * 1e3 if lat else np.array([np.nan])
    ok = np.array(pairs) if pairs else np.full((1, 2), np.nan)
    return {"concurrency": concurrency, "requests": done,
            # Same requests: client latency vs the solve time the server measured.
            "server_solve_p50_ms": float(np.median(ok[:, 1]) * 1e3),
            "http_overhead_p50_ms": float(np.median(ok[:, 0] - ok[:, 1]) * 1e3),
            "latency_over_solve": float(np.sum(ok[:, 0]) / np.sum(ok[:, 1]) - 1),
            "requests_per_s": done / duration_s,
            "p50_ms": float(np.percentile(lat_ms, 50)),
            "p95_ms": float(np.percentile(lat_ms, 95)),
            "p99_ms": float(np.percentile(lat_ms, 99)),
            "errors": int(sum(errors.values())), "error_kinds": errors,
            "localized_fraction": localized / max(done, 1)}


def to_markdown(report: dict[str, Any]) -> str:
    inproc = report["in_process"]
    w = report["workers"]
    lines = [
        "## HTTP load on loopback (`bench/load.py`)",
        "",
        f"`{report['command']}` - {report['frames']} simulated Chess frames (real ground-truth "
        "poses, default detector noise, level-set refinement) posted round-robin to a real "
        f"Uvicorn server ({w} worker process{'es' if w > 1 else ''}, SQLite, default settings: "
        "one solve at a time per process) by closed-loop asyncio httpx clients (one keep-alive "
        "connection each) on the same machine, "
        f"{report['duration_s']:g} s per level after {report['warmup_s']:g} s warm-up. "
        f"Machine: {report['machine']}, load average at start {report['load_average']}"
        " (shared with other jobs: expect noise).",
        "",
        f"In-process `localize()` on the same frames, this process, back to back: "
        f"**{inproc['rate_per_s']:.1f} /s** (p50 {inproc['p50_ms']:.1f} ms, p99 "
        f"{inproc['p99_ms']:.1f} ms, localized {inproc['localized_fraction']:.0%}).",
        "",
        "| concurrency | requests/s | p50 ms | p95 ms | p99 ms | errors | localized "
        "| server solve p50 ms | latency - solve, p50 ms |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for lvl in report["levels"]:
        lines.append(f"| {lvl['concurrency']} | {lvl['requests_per_s']:.1f} | "
                     f"{lvl['p50_ms']:.1f} | {lvl['p95_ms']:.1f} | {lvl['p99_ms']:.1f} | "
                     f"{lvl['errors']} | {lvl['localized_fraction']:.0%} | "
                     f"{lvl['server_solve_p50_ms']:.1f} | {lvl['http_overhead_p50_ms']:.1f} |")
    c1 = next((lv for lv in report["levels"] if lv["concurrency"] == 1), None)
    c8 = next((lv for lv in report["levels"] if lv["concurrency"] == 8), None)
    lines.append("")
    if c1:
        lines.append(f"HTTP path cost per worker (concurrency 1, one request in flight): "
                     f"in-process rate / HTTP rate - 1 = "
                     f"**{report['http_overhead_per_worker']:+.0%}**; on the same requests, "
                     f"client latency / server solve time - 1 = "
                     f"**{c1['latency_over_solve']:+.0%}** "
                     f"({c1['http_overhead_p50_ms']:.1f} ms median per request; target <= +30%). "
                     "The first ratio compares two time windows of a shared machine; the second "
                     "is immune to that drift.")
    if c8:
        met = (c8["requests_per_s"] >= 100 and c8["p99_ms"] <= 150 and c8["errors"] == 0)
        lines.append(f"Target at concurrency 8 (>= 100 localizations/s, p99 <= 150 ms, no "
                     f"errors): **{'met' if met else 'not met'}** "
                     f"({c8['requests_per_s']:.1f}/s, p99 {c8['p99_ms']:.0f} ms, "
                     f"{c8['errors']} errors). The ceiling is {w} x the in-process rate "
                     f"= {w * inproc['rate_per_s']:.0f}/s on an idle machine: throughput is "
                     "bounded by the solver's CPU time, not by the HTTP layer.")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=10.0, help="seconds per level")
    parser.add_argument("--warmup", type=float, default=2.0, help="warm-up seconds per level")
    parser.add_argument("--concurrency", type=int, nargs="+", default=[1, 8, 32])
    parser.add_argument("--workers", type=int, default=2, help="Uvicorn worker processes")
    parser.add_argument("--frames", type=int, default=48, help="distinct frames to cycle")
    parser.add_argument("--json", help="write the JSON report here")
    parser.add_argument("--write-results", action="store_true",
                        help="write the 'load' section of docs/results.md")
    args = parser.parse_args(argv)

    load_average = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    bodies, inputs = build_frames(args.frames)
    inproc = in_process_rate(inputs, args.duration)
    print(f"in-process: {inproc['rate_per_s']:.1f}/s p50 {inproc['p50_ms']:.1f} ms",
          file=sys.stderr)
    levels = []
    with tempfile.TemporaryDirectory(prefix="quadloc-load-") as tmp:
        proc, base = start_server(args.workers, Path(tmp))
        try:
            for c in args.concurrency:
                lvl = run_level(base, bodies, c, args.duration, args.warmup)
                levels.append(lvl)
                print(f"c={c}: {lvl['requests_per_s']:.1f}/s p50 {lvl['p50_ms']:.1f} "
                      f"p99 {lvl['p99_ms']:.1f} ms errors {lvl['errors']}", file=sys.stderr)
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    c1 = next((lv for lv in levels if lv["concurrency"] == 1), None)
    overhead = (inproc["rate_per_s"] / c1["requests_per_s"] - 1) if c1 else None
    command = "python -m bench.load " + " ".join(argv if argv is not None else sys.argv[1:])
    report = {"command": command.strip(), "frames": args.frames, "workers": args.workers,
              "duration_s": args.duration, "warmup_s": args.warmup,
              "machine": f"{os.cpu_count()} CPUs, {platform.python_implementation()} "
                         f"{platform.python_version()}",
              "load_average": load_average, "in_process": inproc, "levels": levels,
              "http_overhead_per_worker": overhead}
    text = json.dumps(report, indent=2)
    if args.json:
        Path(args.json).write_text(text + "\n")
    print(text)
    if args.write_results:
        from bench.results_doc import update_results_section

        update_results_section("load", to_markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
