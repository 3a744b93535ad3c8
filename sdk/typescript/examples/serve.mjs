#!/usr/bin/env node
// A development server for the example pages: serves this package's files (dist/, examples/,
// test/browser/, three.js from node_modules/) and the repository's docs/examples/, and proxies
// the API (/v1/..., /healthz, /readyz, /metrics) to a QuadLoc server, so that pages and API
// share one origin (QuadLoc sends no CORS headers; in production put the app and the API
// behind one origin too, or add CORS at your proxy).
//
//   node examples/serve.mjs --quadloc http://127.0.0.1:8000 --port 8080
//   open http://127.0.0.1:8080/examples/webxr-replay/
//
// Listens on 127.0.0.1 only. Node >= 18, no dependency.
import { createReadStream, statSync } from "node:fs";
import { createServer, request as httpRequest } from "node:http";
import { request as httpsRequest } from "node:https";
import { dirname, extname, join, normalize, sep } from "node:path";
import { fileURLToPath } from "node:url";

const pkg = join(dirname(fileURLToPath(import.meta.url)), "..");
const repo = join(pkg, "..", "..");
const args = Object.fromEntries(
  process.argv.slice(2).reduce((acc, a, i, all) => (a.startsWith("--") ? [...acc, [a.slice(2), all[i + 1]]] : acc), []),
);
const upstream = new URL(args.quadloc ?? process.env.QUADLOC_URL ?? "http://127.0.0.1:8000");
const port = Number(args.port ?? 8080);
const TYPES = {
  ".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8", ".mjs": "text/javascript; charset=utf-8",
  ".json": "application/json", ".map": "application/json", ".css": "text/css", ".png": "image/png", ".svg": "image/svg+xml",
};
// URL prefix -> folder; nothing outside these folders is served.
const ROOTS = [
  ["/docs/examples/", join(repo, "docs", "examples")],
  ["/dist/", join(pkg, "dist")],
  ["/examples/", join(pkg, "examples")],
  ["/test/browser/", join(pkg, "test", "browser")],
  ["/node_modules/three/", join(pkg, "node_modules", "three")],
];
const API = /^\/(v1\/|healthz$|readyz$|metrics$)/;

function serveFile(req, res, pathname) {
  for (const [prefix, root] of ROOTS) {
    if (!pathname.startsWith(prefix)) continue;
    let file = normalize(join(root, decodeURIComponent(pathname.slice(prefix.length))));
    if (file !== root && !file.startsWith(root + sep)) break;
    try {
      if (statSync(file).isDirectory()) file = join(file, "index.html");
      const size = statSync(file).size;
      res.writeHead(200, { "Content-Type": TYPES[extname(file)] ?? "application/octet-stream", "Content-Length": size, "Cache-Control": "no-store" });
      createReadStream(file).pipe(res);
      return;
    } catch {
      break;
    }
  }
  res.writeHead(404, { "Content-Type": "text/plain" });
  res.end(`not found: ${pathname}\n`);
}

function proxy(req, res) {
  const send = upstream.protocol === "https:" ? httpsRequest : httpRequest;
  const headers = { ...req.headers, host: upstream.host };
  const out = send(
    { protocol: upstream.protocol, hostname: upstream.hostname, port: upstream.port, method: req.method, path: req.url, headers },
    (answer) => {
      res.writeHead(answer.statusCode ?? 502, answer.headers);
      answer.pipe(res);
    },
  );
  out.on("error", (err) => {
    res.writeHead(502, { "Content-Type": "application/problem+json" });
    res.end(JSON.stringify({ type: "about:blank", title: "Bad gateway", status: 502, detail: `QuadLoc at ${upstream.origin}: ${err.message}` }));
  });
  req.pipe(out);
}

const server = createServer((req, res) => {
  const { pathname } = new URL(req.url ?? "/", "http://localhost");
  if (API.test(pathname)) proxy(req, res);
  else if (pathname === "/") {
    res.writeHead(302, { Location: "/examples/webxr-replay/" });
    res.end();
  } else serveFile(req, res, pathname);
});
server.listen(port, "127.0.0.1", () => {
  console.log(`serving http://127.0.0.1:${server.address().port}/ (API -> ${upstream.origin})`);
});
for (const sig of ["SIGINT", "SIGTERM"]) process.on(sig, () => server.close(() => process.exit(0)));
