"""The HTTP surface a client reaches without a key, against a real ``quadloc serve`` on
loopback (issue 32, items 3 and 7).

Run::

    .venv/bin/python -m bench.http_surface [--methods 200] [--method-bytes 16000]
        [--json out.json] [--write-results]

1. Starts ``quadloc serve`` (``python -m quadloc.service serve``, default settings, open on
   loopback, temporary SQLite database).
2. Metrics labels: sends ``--methods`` requests to ``/healthz``, each with a distinct method
   name of ``--method-bytes`` bytes (``FOO000XXXX...``), then reads ``/metrics``: its size in
   bytes and the number of ``quadloc_http_requests_total`` series. Before issue 32 each method
   was a label value (200 x 16 KB methods: a 71 MB page); the target is a page that does not
   grow with the methods sent.
3. Header limit (``QUADLOC_MAX_HEADER_BYTES``, default 32,768): one request per size whose
   request line + headers are sent in ONE write, and the status line answered. Before issue 32
   a 60 KB or 120 KB head sent at once was answered 200; the target is 200 up to the limit and
   400 (connection closed) over it.

Prints JSON; ``--write-results`` writes the ``http-surface`` section of docs/results.md.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

from bench.load import _free_port, wait_until_ready

REPO = Path(__file__).resolve().parents[1]
HEAD_SIZES = (16_000, 32_000, 33_000, 60_000, 120_000)
MAX_HEADER_BYTES = 32_768


def _serve(data_dir: Path) -> tuple[subprocess.Popen[bytes], str]:
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("QUADLOC_")}
    env.update({"QUADLOC_DATABASE_URL": f"sqlite:///{data_dir / 'surface.db'}",
                "QUADLOC_DATA_DIR": str(data_dir),
                "QUADLOC_LOG_LEVEL": "warning"})
    log = open(data_dir / "server.log", "wb")  # noqa: SIM115 - lives with the server
    proc = subprocess.Popen(
        [sys.executable, "-m", "quadloc.service", "serve", "--host", "127.0.0.1", "--port",
         str(port)], cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    wait_until_ready(proc, base, data_dir / "server.log")
    return proc, base


def _head_in_one_write(base: str, pad: int) -> tuple[int, str]:
    """(bytes of the request head, status line answered) for a GET /healthz whose head holds
    an ``X-Pad`` header of ``pad`` bytes, sent in one ``sendall``."""
    host, port = base.removeprefix("http://").split(":")
    head = (b"GET /healthz HTTP/1.1\r\nHost: t\r\nX-Pad: " + b"a" * pad
            + b"\r\nConnection: close\r\n\r\n")
    with socket.create_connection((host, int(port)), timeout=10) as s:
        s.sendall(head)
        data = b""
        while True:
            try:
                chunk = s.recv(65536)
            except ConnectionResetError:
                break
            if not chunk:
                break
            data += chunk
    return len(head), data.split(b"\r\n", 1)[0].decode("latin-1")


def run(methods: int, method_bytes: int) -> dict[str, Any]:
    """The measurements of the module docstring."""
    with tempfile.TemporaryDirectory(prefix="quadloc-surface-") as tmp:
        proc, base = _serve(Path(tmp))
        try:
            with httpx.Client(base_url=base, timeout=30) as client:
                statuses: dict[str, int] = {}
                for i in range(methods):
                    name = f"FOO{i:03d}" + "X" * max(0, method_bytes - 6)
                    code = str(client.request(name, "/healthz").status_code)
                    statuses[code] = statuses.get(code, 0) + 1
                page = client.get("/metrics").text
            series = re.findall(r"^quadloc_http_requests_total\{([^}]*)\}", page, re.M)
            methods_seen = sorted({m for s in series for m in re.findall(r'method="([^"]*)"', s)})
            heads = []
            for pad in HEAD_SIZES:
                size, status = _head_in_one_write(base, pad)
                heads.append({"head_bytes": size, "status": status,
                              "over_limit": size > MAX_HEADER_BYTES})
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    return {"methods_sent": methods, "method_bytes": method_bytes, "statuses": statuses,
            "metrics_bytes": len(page.encode()), "request_series": len(series),
            "method_labels": [m[:16] for m in methods_seen],
            "max_header_bytes": MAX_HEADER_BYTES, "heads_in_one_write": heads,
            "heads_ok": all(h["status"].startswith("HTTP/1.1 400") == h["over_limit"]
                            for h in heads)}


def to_markdown(report: dict[str, Any]) -> str:
    """The ``http-surface`` section of docs/results.md."""
    lines = ["## HTTP surface without a key (issue 32)", "",
             f"{report['methods_sent']} requests to `/healthz`, each with a distinct method of "
             f"{report['method_bytes']} bytes, then `GET /metrics`: "
             f"**{report['metrics_bytes']:,} bytes**, {report['request_series']} "
             f"`quadloc_http_requests_total` series, method labels "
             f"{', '.join(f'`{m}`' for m in report['method_labels'])} (before issue 32: one "
             "series per method sent, a 71 MB page for the same requests).", "",
             f"Request heads sent in one write (`QUADLOC_MAX_HEADER_BYTES` = "
             f"{report['max_header_bytes']:,}; before issue 32 a 60 KB or 120 KB head sent at "
             "once was answered 200):", "",
             "| head bytes | over the limit | answer |", "|---|---|---|"]
    lines += [f"| {h['head_bytes']:,} | {'yes' if h['over_limit'] else 'no'} | "
              f"`{h['status']}` |" for h in report["heads_in_one_write"]]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--methods", type=int, default=200)
    parser.add_argument("--method-bytes", type=int, default=16_000)
    parser.add_argument("--json", type=Path, help="also write the report here")
    parser.add_argument("--write-results", action="store_true",
                        help="write the http-surface section of docs/results.md")
    args = parser.parse_args(argv)
    t0 = time.monotonic()
    report = run(args.methods, args.method_bytes)
    report["seconds"] = round(time.monotonic() - t0, 1)
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")
    if args.write_results:
        from bench.results_doc import update_results_section

        update_results_section("http-surface", to_markdown(report))
    return 0 if report["heads_ok"] and report["request_series"] < 20 else 1


if __name__ == "__main__":
    sys.exit(main())
