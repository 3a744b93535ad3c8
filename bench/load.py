"""Sustained localization load on loopback: real Uvicorn replicas, asyncio httpx clients.

Run::

    .venv/bin/python -m bench.load [--duration 10] [--concurrency 1 8 32] [--workers 2]
                                   [--frames 48] [--json out.json] [--write-results]
                                   [--baseline DIR] [--set QUADLOC_X=V ...]
                                   [--baseline-set QUADLOC_X=V ...]

``--baseline DIR`` serves another checkout (e.g. ``git worktree add DIR main``) the same way and
runs every level against both, in alternation, so the comparison shares the machine's load.
``--set`` / ``--baseline-set`` give settings to this checkout's / the baseline's replicas (to
measure a setting before changing its default: ``--baseline .`` and ``--set`` on one side).

What it does, in one run (so the numbers are comparable on a noisy shared machine):

1. Simulates ``--frames`` frames of the demo Chess map at real ground-truth poses
   (``chess_test_poses.json``, evenly spaced; ``tests.support.simulate`` default detector noise) and
   builds their ``POST /v1/maps/chess/localize`` bodies.
2. **In process**: calls ``quadloc.service.localization.pipeline.localize`` on the same frames (same
   options) back to back in this process, ``--duration`` seconds in all: half before the first
   level, half right after it (the CPU time of a call depends on what else runs on the shared
   machine, so the windows bracket the concurrency-1 level it is compared with): the
   per-worker ceiling.
3. Starts ``--workers`` W single-worker ``uvicorn quadloc.service.api.app:create_app --factory``
   replicas on free loopback ports, sharing a temporary SQLite database, default settings
   (``QUADLOC_MAX_CONCURRENT_SOLVES`` = 2 solves at a time per process, first come first
   served).
   This is the documented deployment: one process per container, replicas behind a load
   balancer. (``uvicorn --workers 2`` was measured first: its processes accept keep-alive
   connections unevenly - e.g. 24 of 32 on one process - and that process's queue sets p99.)
4. For each concurrency ``c``: ``c`` closed-loop asyncio clients (one ``httpx.AsyncClient``
   keep-alive pool) post the frames in turn for ``--duration`` seconds (after a short
   warm-up), each request to the replica with the fewest requests in flight (a load balancer in
   least-connections mode). Reports requests/s, latency p50/p95/p99 (ms, client-measured),
   errors (transport errors, non-200 answers, or bodies that do not parse), the localized
   fraction, and for the same requests the server's solve time (``timings_ms.total``).

HTTP overhead per worker = ``in-process rate / (HTTP rate at concurrency 1)`` - 1: at
concurrency 1 only one request is in flight, so one worker serves it and the difference is the
HTTP path (parsing, validation, serialisation, loopback, client, thread hand-offs). The two
rates come from different time windows of a shared machine; "latency - solve" on the same
requests does not. The client runs on the same 2 cores as the server and takes CPU from it.
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


def build_frames(n_frames: int, seed: int = 0) -> tuple[list[dict[str, Any]], list[Any]]:
    """``n_frames`` request bodies (and the matching in-process inputs) of simulated frames."""
    from quadloc.factors.rotations import invert_pose
    from quadloc.maps.compiled import compile_map
    from quadloc.maps.demo import load_demo_map
    from quadloc.service.app.conversions import (
        camera_from_request,
        detections_from_request,
        options_from_request,
    )
    from quadloc.service.schemas.localize import LocalizeRequest
    from tests.support.reference_data import load_chess_poses
    from tests.support.simulate import simulate_frame

    camera, camera_from_world, names = load_chess_poses()
    compiled = compile_map(load_demo_map())
    picks = np.linspace(0, len(camera_from_world) - 1, n_frames).round().astype(int)
    bodies, inputs = [], []
    for k, i in enumerate(picks):
        world_from_camera = invert_pose(camera_from_world[int(i)])
        sim = simulate_frame(compiled, camera, world_from_camera, seed + k)
        body = {
            "camera": {"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
                       "width": camera.width, "height": camera.height},
            "detections": [{"ellipse": {"cx": d.ellipse.cx, "cy": d.ellipse.cy,
                                        "a": d.ellipse.a, "b": d.ellipse.b,
                                        "angle": d.ellipse.angle},
                            "label": d.label,
                            **({"sigma": d.sigma} if d.sigma is not None else {})}
                           for d in sim.detections],
            "frame_id": names[int(i)],
        }
        req = LocalizeRequest.model_validate(body)
        bodies.append(body)
        inputs.append((detections_from_request(req.detections), compiled,
                       camera_from_request(req.camera), options_from_request(req.options,
                                                                             1000.0)))
    return bodies, inputs


def in_process_window(inputs: list[Any], duration_s: float) -> dict[str, Any]:
    """Back-to-back ``localize()`` calls for ``duration_s``: raw latencies (s), localized count
    and CPU seconds of this process (summarised by :func:`in_process_rate`)."""
    from quadloc.service.localization.pipeline import localize

    for args in inputs[:4]:  # warm caches
        localize(*args)
    lat, localized = [], 0
    t_end = time.perf_counter() + duration_s
    i = 0
    cpu0 = time.process_time()
    while time.perf_counter() < t_end:
        t0 = time.perf_counter()
        result = localize(*inputs[i % len(inputs)])
        lat.append(time.perf_counter() - t0)
        localized += int(result.localized)
        i += 1
    return {"lat": lat, "localized": localized, "cpu_s": time.process_time() - cpu0}


def in_process_rate(windows: list[dict[str, Any]]) -> dict[str, Any]:
    """Rate, CPU per call and latency percentiles over :func:`in_process_window` windows."""
    lat = [x for w in windows for x in w["lat"]]
    calls = max(len(lat), 1)
    cpu_ms = sum(w["cpu_s"] for w in windows) * 1e3 / calls
    lat_ms = np.array(lat) * 1e3
    return {"calls": len(lat), "rate_per_s": len(lat) / float(np.sum(lat)),
            "cpu_ms_per_call": cpu_ms, "cpu_rate_per_core": 1e3 / cpu_ms,
            "window_cpu_ms_per_call": [w["cpu_s"] * 1e3 / max(len(w["lat"]), 1)
                                       for w in windows],
            "p50_ms": float(np.percentile(lat_ms, 50)),
            "p95_ms": float(np.percentile(lat_ms, 95)),
            "p99_ms": float(np.percentile(lat_ms, 99)),
            "localized_fraction": sum(w["localized"] for w in windows) / calls}


def process_cpu_s(pid: int) -> float:
    """User + system CPU seconds used so far by process ``pid`` (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_server(data_dir: Path, port: int | None = None, tree: Path = REPO,
                 settings: dict[str, str] | None = None) -> tuple[subprocess.Popen, str]:
    """One real Uvicorn process (one worker) on a loopback port, running the code of ``tree``
    (this checkout by default) with default settings plus ``settings`` (``QUADLOC_*``
    variables); returns (process, base URL)."""
    from bench.results_doc import tree_python

    port = port or _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("QUADLOC_")}
    env.update({"QUADLOC_DATABASE_URL": f"sqlite:///{data_dir / 'load.db'}",
                "QUADLOC_DATA_DIR": str(data_dir), "PYTHONPATH": str(tree), **(settings or {})})
    log = open(data_dir / f"uvicorn-{port}.log", "wb")  # noqa: SIM115 - lives with the server
    proc = subprocess.Popen(
        [tree_python(tree), "-m", "uvicorn", "quadloc.service.api.app:create_app", "--factory",
         "--host", "127.0.0.1", "--port", str(port), "--log-level", "warning",
         "--no-access-log"],
        cwd=tree, env=env, stdout=log, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    wait_until_ready(proc, base, data_dir / f"uvicorn-{port}.log")
    return proc, base


def wait_until_ready(proc: subprocess.Popen, base: str, log_path: Path,
                     timeout_s: float = 120.0) -> None:
    """Poll ``{base}/readyz`` until 200; raise with the log's tail if the server exits, and
    terminate it if it is not ready within ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(log_path.read_text()[-3000:])
        try:
            if httpx.get(f"{base}/readyz", timeout=2).status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    proc.terminate()
    raise RuntimeError("server did not become ready")


def start_replicas(n: int, data_dir: Path, tree: Path = REPO,
                   settings: dict[str, str] | None = None
                   ) -> tuple[list[subprocess.Popen], list[str]]:
    """``n`` single-worker Uvicorn replicas (code of ``tree``, ``settings`` as in
    :func:`start_server`) sharing one SQLite database."""
    procs, bases = [], []
    try:
        for _ in range(n):
            proc, base = start_server(data_dir, tree=tree, settings=settings)
            procs.append(proc)
            bases.append(base)
    except Exception:
        for proc in procs:
            proc.terminate()
        raise
    return procs, bases


def run_level(bases: list[str], bodies: list[dict[str, Any]], concurrency: int,
              duration_s: float, warmup_s: float,
              server_pids: list[int] | None = None) -> dict[str, Any]:
    """``concurrency`` closed-loop clients (asyncio tasks sharing one keep-alive
    ``httpx.AsyncClient`` pool) posting frames for ``duration_s`` after a warm-up. Each request
    goes to the replica with the fewest requests in flight (what a load balancer in
    least-connections mode does). Asyncio rather than threads: the client shares the 2 cores
    with the server, and 32 Python threads would spend CPU fighting over the GIL."""
    pids = server_pids or []
    server0 = sum(process_cpu_s(p) for p in pids)
    client0 = time.process_time()
    wall0 = time.perf_counter()
    out = asyncio.run(_run_level(bases, bodies, concurrency, duration_s, warmup_s))
    wall = time.perf_counter() - wall0
    # CPU per request over the whole level (warm-up included in both numerator and the count
    # of requests sent, so the ratio is unbiased): immune to other jobs on the machine.
    sent = out.pop("sent")
    if pids and sent:
        out["server_cpu_ms_per_request"] = (sum(process_cpu_s(p) for p in pids) - server0) \
            * 1e3 / sent
    client_cpu = time.process_time() - client0
    out["client_cpu_ms_per_request"] = client_cpu * 1e3 / max(sent, 1)
    if pids:  # how many cores server + client actually got (the rest went to other jobs)
        out["cores_obtained"] = (out["server_cpu_ms_per_request"] * sent / 1e3
                                 + client_cpu) / wall
    return out


async def _run_level(bases: list[str], bodies: list[dict[str, Any]], concurrency: int,
                     duration_s: float, warmup_s: float) -> dict[str, Any]:
    urls = [f"{base}/v1/maps/chess/localize" for base in bases]
    in_flight = [0] * len(urls)
    payloads = [json.dumps(b).encode() for b in bodies]
    start = time.perf_counter() + warmup_s
    stop = start + duration_s
    lat: list[float] = []
    pairs: list[tuple[float, float]] = []  # (client latency, server solve time) of OK answers
    errors: dict[str, int] = {}  # kind -> count, over every request sent
    errors_outside = [0]  # of which in the warm-up or straddling the window's edges
    localized = 0
    sent = 0
    n_conn = concurrency * len(urls)
    limits = httpx.Limits(max_connections=n_conn, max_keepalive_connections=n_conn)

    async def client_loop(client: httpx.AsyncClient, k: int) -> None:
        nonlocal localized, sent
        i = k
        while True:
            t0 = time.perf_counter()
            if t0 >= stop:
                return
            kind, body = None, None
            target = min(range(len(urls)), key=in_flight.__getitem__)
            in_flight[target] += 1
            try:
                r = await client.post(urls[target], content=payloads[i % len(payloads)],
                                      headers={"content-type": "application/json"})
                if r.status_code == 200:
                    body = r.json()
                else:
                    kind = f"http_{r.status_code}"
            except (httpx.HTTPError, ValueError) as exc:
                kind = type(exc).__name__
            finally:
                in_flight[target] -= 1
            t1 = time.perf_counter()
            i += concurrency
            sent += 1
            failed = bool(kind) or body is None
            if failed:  # every error counts, also in the warm-up and across the window edges
                errors[kind or "no_body"] = errors.get(kind or "no_body", 0) + 1
            if t0 < start or t1 > stop:  # warm-up or straddling an edge: no latency/throughput
                if failed:
                    errors_outside[0] += 1
                continue
            lat.append(t1 - t0)
            if not failed:
                assert body is not None
                pairs.append((t1 - t0, body["timings_ms"]["total"] / 1e3))
                localized += int(bool(body.get("localized")))

    async with httpx.AsyncClient(timeout=30.0, limits=limits) as client:
        await asyncio.gather(*(client_loop(client, k) for k in range(concurrency)))
    done = len(lat)
    lat_ms = np.array(lat) * 1e3 if lat else np.array([np.nan])
    ok = np.array(pairs) if pairs else np.full((1, 2), np.nan)
    return {"concurrency": concurrency, "requests": done, "sent": sent,
            # Same requests: client latency vs the solve time the server measured.
            "server_solve_p50_ms": float(np.median(ok[:, 1]) * 1e3),
            "http_overhead_p50_ms": float(np.median(ok[:, 0] - ok[:, 1]) * 1e3),
            "latency_over_solve": float(np.sum(ok[:, 0]) / np.sum(ok[:, 1]) - 1),
            "requests_per_s": done / duration_s,
            "p50_ms": float(np.percentile(lat_ms, 50)),
            "p95_ms": float(np.percentile(lat_ms, 95)),
            "p99_ms": float(np.percentile(lat_ms, 99)),
            "errors": int(sum(errors.values())), "error_kinds": errors,
            "errors_outside_window": errors_outside[0],
            "localized_fraction": localized / max(done, 1)}


def to_markdown(report: dict[str, Any]) -> str:
    inproc = report["in_process"]
    w = report["workers"]
    lines = [
        "## HTTP load on loopback (`bench/load.py`)",
        "",
        f"{report['frames']} simulated Chess frames (real ground-truth "
        f"poses, default detector noise, level-set refinement) posted to {w} real single-worker "
        "Uvicorn replica(s) (shared SQLite, default settings: `QUADLOC_MAX_CONCURRENT_SOLVES` = "
        "2 solves at a time per process) "
        "by closed-loop asyncio httpx clients on the same machine, each request to the replica "
        "with the fewest in flight (least-connections balancing), "
        f"{report['duration_s']:g} s per level after {report['warmup_s']:g} s warm-up. "
        f"Machine: {report['machine']}, load average at start {report['load_average']}"
        " (shared with other jobs: expect noise)."
        + (f" Settings of this checkout's replicas: `{' '.join(report['settings'])}`."
           if report.get("settings") else "")
        + (f" Settings of the baseline's replicas: `{' '.join(report['baseline_settings'])}`."
           if report.get("baseline_settings") else ""),
        "",
        f"In-process `localize()` on the same frames, this process, back to back (two windows "
        f"of {report['duration_s'] / 2:g} s, before and after the first level): "
        f"**{inproc['rate_per_s']:.1f} /s** (p50 {inproc['p50_ms']:.1f} ms, p99 "
        f"{inproc['p99_ms']:.1f} ms, localized {inproc['localized_fraction']:.0%}); "
        f"CPU time {inproc['cpu_ms_per_call']:.2f} ms per call ("
        + " / ".join(f"{x:.2f}" for x in inproc.get("window_cpu_ms_per_call", [])) +
        f" in the two windows), i.e. "
        f"{inproc['cpu_rate_per_core']:.0f} /s per fully available core.",
        "",
        "CPU columns: CPU seconds used by the server processes (from `/proc`) and by the client "
        "process during the level, divided by the requests sent; unlike wall-clock rates they do "
        "not depend on what else runs on the machine. \"cores obtained\": CPU seconds used by "
        "server + client per wall-clock second (of the machine's "
        f"{os.cpu_count()}; the rest went to other jobs).",
        "",
        "| concurrency | requests/s | p50 ms | p95 ms | p99 ms | errors | localized "
        "| server solve p50 ms | latency - solve, p50 ms | server CPU ms/request "
        "| client CPU ms/request | cores obtained |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for lvl in report["levels"]:
        lines.append(f"| {lvl['concurrency']} | {lvl['requests_per_s']:.1f} | "
                     f"{lvl['p50_ms']:.1f} | {lvl['p95_ms']:.1f} | {lvl['p99_ms']:.1f} | "
                     f"{lvl['errors']} | {lvl['localized_fraction']:.0%} | "
                     f"{lvl['server_solve_p50_ms']:.1f} | {lvl['http_overhead_p50_ms']:.1f} | "
                     f"{lvl.get('server_cpu_ms_per_request', float('nan')):.2f} | "
                     f"{lvl['client_cpu_ms_per_request']:.2f} | "
                     f"{lvl.get('cores_obtained', float('nan')):.2f} |")
    if report.get("baseline_levels"):
        lines += ["", f"Baseline in the same run (`--baseline {report['baseline']}`, served the "
                      "same way, each level right before or after this checkout's):", "",
                  "| concurrency | baseline requests/s | this requests/s | ratio | baseline "
                  "p99 ms | this p99 ms | baseline server CPU ms/request | this server CPU "
                  "ms/request |", "|---|---|---|---|---|---|---|---|"]
        for b, t in zip(report["baseline_levels"], report["levels"], strict=True):
            lines.append(
                f"| {t['concurrency']} | {b['requests_per_s']:.1f} | {t['requests_per_s']:.1f} "
                f"| x{t['requests_per_s'] / max(b['requests_per_s'], 1e-9):.2f} | "
                f"{b['p99_ms']:.1f} | {t['p99_ms']:.1f} | "
                f"{b.get('server_cpu_ms_per_request', float('nan')):.2f} | "
                f"{t.get('server_cpu_ms_per_request', float('nan')):.2f} |")
        t8 = next((lv for lv in report["levels"] if lv["concurrency"] == 8), None)
        b8 = next((lv for lv in report["baseline_levels"] if lv["concurrency"] == 8), None)
        if t8 and b8:
            ratio = t8["requests_per_s"] / max(b8["requests_per_s"], 1e-9)
            met = t8["p99_ms"] <= 60.0 and t8["errors"] == 0
            lines += ["", f"At concurrency 8, this checkout against the baseline in the same "
                          f"run: throughput x{ratio:.2f}, p99 {t8['p99_ms']:.0f} ms vs "
                          f"{b8['p99_ms']:.0f} ms. Issue 14's p99 <= 60 ms (and no errors): "
                          f"**{'met' if met else 'not met'} in this run** (its other target, "
                          ">= 2 x the throughput of the tree it was filed against, is a "
                          "comparison with that tree: run with `--baseline` on it)."]
    c1 = next((lv for lv in report["levels"] if lv["concurrency"] == 1), None)
    c8 = next((lv for lv in report["levels"] if lv["concurrency"] == 8), None)
    lines.append("")
    if c1:
        lines.append(
            f"HTTP path cost per worker (concurrency 1, one request in flight): wall clock, "
            f"in-process rate / HTTP rate - 1 = **{report['http_overhead_per_worker']:+.0%}**; "
            f"same requests, client latency / server solve time - 1 = "
            f"**{c1['latency_over_solve']:+.0%}** ({c1['http_overhead_p50_ms']:.1f} ms median); "
            f"CPU, server CPU per request / in-process CPU per call - 1 = "
            f"**{report['http_cpu_overhead_per_worker']:+.0%}** (target <= +30%).")
    if c8:
        met = (c8["requests_per_s"] >= 100 and c8["p99_ms"] <= 150 and c8["errors"] == 0)
        server_cpu = c8.get("server_cpu_ms_per_request", float("nan"))
        client_cpu = c8["client_cpu_ms_per_request"]
        lines.append("")
        lines.append(
            f"Target at concurrency 8 (>= 100 localizations/s, p99 <= 150 ms, no errors): "
            f"**{'met' if met else 'not met'} in this run** ({c8['requests_per_s']:.1f}/s, p99 "
            f"{c8['p99_ms']:.0f} ms, {c8['errors']} errors, machine load average "
            f"{report['load_average']}). CPU capacity of {os.cpu_count()} dedicated cores at "
            f"the measured CPU cost: {os.cpu_count() * 1e3 / server_cpu:.0f}/s for the server "
            f"alone, {os.cpu_count() * 1e3 / (server_cpu + client_cpu):.0f}/s with this Python "
            "client on the same cores: throughput is bounded by the solver's CPU time, and the "
            "wall-clock numbers above by the CPU the other jobs leave.")
    return "\n".join(lines)


def _settings(pairs: list[str]) -> dict[str, str]:
    """``["QUADLOC_X=1", ...]`` -> ``{"QUADLOC_X": "1"}`` (only ``QUADLOC_*`` names)."""
    out = dict(pair.split("=", 1) for pair in pairs)
    bad = [k for k in out if not k.startswith("QUADLOC_")]
    if bad:
        raise SystemExit(f"--set/--baseline-set take QUADLOC_* variables, not {bad}")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=10.0, help="seconds per level")
    parser.add_argument("--warmup", type=float, default=2.0, help="warm-up seconds per level")
    parser.add_argument("--concurrency", type=int, nargs="+", default=[1, 8, 32])
    parser.add_argument("--workers", type=int, default=2,
                        help="single-worker Uvicorn replicas (one per core)")
    parser.add_argument("--frames", type=int, default=48, help="distinct frames to cycle")
    parser.add_argument("--json", help="write the JSON report here")
    parser.add_argument("--write-results", action="store_true",
                        help="write the 'load' section of docs/results.md")
    parser.add_argument("--baseline", type=Path,
                        help="another checkout (e.g. a git worktree of main) served the same "
                             "way, level by level in alternation with this one")
    parser.add_argument("--set", nargs="+", default=[], metavar="QUADLOC_X=VALUE",
                        help="settings of this checkout's replicas (default: none)")
    parser.add_argument("--baseline-set", nargs="+", default=[], metavar="QUADLOC_X=VALUE",
                        help="settings of the baseline's replicas (default: none)")
    args = parser.parse_args(argv)
    settings = [_settings(args.set), _settings(args.baseline_set)]

    load_average = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    bodies, inputs = build_frames(args.frames)
    # In process: half right before the first level, half right after it (the CPU time of a
    # call depends on what else runs on the machine: bracket the level it is compared with).
    windows = [in_process_window(inputs, args.duration / 2)]
    levels: list[dict[str, Any]] = []
    baseline_levels: list[dict[str, Any]] = []
    trees = [(REPO, levels)] + ([(args.baseline.resolve(), baseline_levels)]
                               if args.baseline else [])
    with tempfile.TemporaryDirectory(prefix="quadloc-load-") as tmp:
        servers = []
        try:
            for k, (tree, _) in enumerate(trees):
                (Path(tmp) / str(k)).mkdir()
                servers.append(start_replicas(args.workers, Path(tmp) / str(k), tree,
                                              settings[k]))
            for i, c in enumerate(args.concurrency):
                # with a baseline: both trees at each level, in alternating order
                order = list(zip(trees, servers, strict=True))
                for (tree, out), (procs, bases) in (order if i % 2 == 0 else order[::-1]):
                    lvl = run_level(bases, bodies, c, args.duration, args.warmup,
                                    [p.pid for p in procs])
                    out.append(lvl)
                    print(f"{tree.name} c={c}: {lvl['requests_per_s']:.1f}/s p50 "
                          f"{lvl['p50_ms']:.1f} p99 {lvl['p99_ms']:.1f} ms errors "
                          f"{lvl['errors']}", file=sys.stderr)
                if i == 0:
                    windows.append(in_process_window(inputs, args.duration / 2))
        finally:
            for procs, _ in servers:
                for proc in procs:
                    proc.terminate()
            for procs, _ in servers:
                for proc in procs:
                    proc.wait(timeout=30)
    inproc = in_process_rate(windows)
    print(f"in-process: {inproc['rate_per_s']:.1f}/s p50 {inproc['p50_ms']:.1f} ms",
          file=sys.stderr)
    c1 = next((lv for lv in levels if lv["concurrency"] == 1), None)
    overhead = (inproc["rate_per_s"] / c1["requests_per_s"] - 1) if c1 else None
    cpu_overhead = (c1["server_cpu_ms_per_request"] / inproc["cpu_ms_per_call"] - 1
                    if c1 and "server_cpu_ms_per_request" in c1 else None)
    command = "python -m bench.load " + " ".join(argv if argv is not None else sys.argv[1:])
    from bench.results_doc import tree_version

    report = {"command": command.strip(), "frames": args.frames, "workers": args.workers,
              "duration_s": args.duration, "warmup_s": args.warmup,
              "machine": f"{os.cpu_count()} CPUs, {platform.python_implementation()} "
                         f"{platform.python_version()}",
              "load_average": load_average, "in_process": inproc, "levels": levels,
              **({"settings": args.set} if args.set else {}),
              **({"baseline_settings": args.baseline_set} if args.baseline_set else {}),
              **({"baseline": f"{args.baseline} ({tree_version(Path(args.baseline))})",
                  "baseline_levels": baseline_levels} if args.baseline else {}),
              "http_overhead_per_worker": overhead,
              "http_cpu_overhead_per_worker": cpu_overhead}
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
