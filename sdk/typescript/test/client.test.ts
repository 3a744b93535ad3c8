// The client against a mocked fetch: every documented problem type maps to its error class
// (sdk/test-vectors/problems.json, shared with the Python and C# SDKs), retries on 429 / 503
// honour Retry-After and stop where they must, timeouts and cancellation, bad arguments.
import assert from "node:assert/strict";
import { describe, it } from "node:test";
import * as sdk from "../dist/index.js";
import { ApiError, InvalidArgumentError, parseRetryAfter, QuadLocClient, RetryPolicy, TimeoutError, TransportError } from "../dist/index.js";
import { readJson } from "./support.js";

const problems: { slug: string; type: string; status: number; title: string; error: string }[] =
  readJson("sdk/test-vectors/problems.json").problems;
const demo = readJson("docs/examples/localize_chess.json");

type Handler = (url: string, init: RequestInit, attempt: number) => Response | Promise<Response>;

/** A client whose fetch is `handler`; records the requests. */
function mocked(handler: Handler, options: Partial<ConstructorParameters<typeof QuadLocClient>[0]> = {}) {
  const calls: { url: string; init: RequestInit }[] = [];
  const client = new QuadLocClient({
    baseUrl: "http://quadloc.test",
    ...options,
    retry: { initialBackoffMs: 1, maxBackoffMs: 2, ...((options.retry as object) ?? {}) },
    fetch: (async (input: string | URL | Request, init?: RequestInit) => {
      calls.push({ url: String(input), init: init ?? {} });
      return handler(String(input), init ?? {}, calls.length);
    }) as typeof fetch,
  });
  return { client, calls };
}

function problem(status: number, slug: string, extra: Record<string, unknown> = {}, headers: Record<string, string> = {}): Response {
  const body = { type: `urn:quadloc:problem:${slug}`, title: slug, status, detail: `${slug} happened`, instance: "/v1/x", ...extra };
  return new Response(JSON.stringify(body), { status, headers: { "content-type": "application/problem+json", ...headers } });
}

function ok(body: unknown, headers: Record<string, string> = {}): Response {
  return new Response(JSON.stringify(body), { status: 200, headers: { "content-type": "application/json", ...headers } });
}

describe("problem documents -> typed errors", () => {
  it("every documented problem type maps to the class of the shared vectors", async () => {
    assert.ok(problems.length >= 20);
    for (const p of problems) {
      const { client } = mocked(() => problem(p.status, p.slug, { errors: [{ field: "camera.fx", message: "bad" }] }, { "retry-after": "0" }), {
        retry: { maxAttempts: 1 },
      });
      const err = await client.localize("chess", demo).then(
        () => assert.fail(`${p.slug}: no error`),
        (e: unknown) => e,
      );
      const cls = (sdk as Record<string, unknown>)[p.error] as new (...a: never[]) => ApiError;
      assert.ok(typeof cls === "function", `no error class ${p.error}`);
      assert.ok(err instanceof cls, `${p.slug} (${p.status}): ${(err as Error).constructor.name}, expected ${p.error}`);
      assert.ok(err instanceof ApiError);
      assert.equal(err.status, p.status);
      assert.equal(err.type, p.type);
      assert.equal(err.slug, p.slug);
      assert.deepEqual(err.fields, ["camera.fx"]);
      assert.equal(err.instance, "/v1/x");
      assert.equal(err.name, p.error);
      assert.match(err.message, new RegExp(`${p.status} .*camera\\.fx: bad`));
    }
  });

  it("the class hierarchy is the Python SDK's", () => {
    assert.ok(new sdk.PreconditionFailed({ status: 412, method: "PUT", url: "u", problem: null }) instanceof sdk.Conflict);
    assert.ok(new sdk.PreconditionRequired({ status: 428, method: "PUT", url: "u", problem: null }) instanceof sdk.Conflict);
    assert.ok(new sdk.ServiceUnavailable({ status: 503, method: "GET", url: "u", problem: null }) instanceof sdk.ServerError);
    assert.ok(new sdk.RateLimited({ status: 429, method: "GET", url: "u", problem: null }) instanceof sdk.ClientError);
  });

  it("a non-JSON error page is kept as text", async () => {
    const { client } = mocked(() => new Response("<html>bad gateway</html>", { status: 502, headers: { "content-type": "text/html" } }));
    await assert.rejects(client.listMaps(), (e: unknown) => e instanceof sdk.ServerError && e.status === 502 && e.text.includes("bad gateway") && e.fields.length === 0);
  });
});

describe("retries", () => {
  it("429 then 503 then 200: retried, waiting at least Retry-After", async () => {
    const t0 = Date.now();
    const { client, calls } = mocked((_u, _i, n) =>
      n === 1 ? problem(429, "rate-limited", {}, { "retry-after": "0.3" }) : n === 2 ? problem(503, "busy", {}, { "retry-after": "0" }) : ok({ maps: [] }),
    );
    assert.deepEqual(await client.listMaps(), []);
    assert.equal(calls.length, 3);
    assert.ok(Date.now() - t0 >= 290, `waited ${Date.now() - t0} ms, Retry-After said 300`);
  });

  it("gives up after maxAttempts with the last error and the attempts made", async () => {
    const { client, calls } = mocked(() => problem(503, "busy", {}, { "retry-after": "0" }), { retry: { maxAttempts: 3 } });
    await assert.rejects(client.localize("chess", demo), (e: unknown) => e instanceof sdk.ServiceUnavailable && e.attempts === 3 && e.retryAfterS === 0);
    assert.equal(calls.length, 3);
  });

  it("a Retry-After above maxRetryAfterMs is not waited for", async () => {
    const { client, calls } = mocked(() => problem(429, "rate-limited", {}, { "retry-after": "120" }));
    const t0 = Date.now();
    await assert.rejects(client.listMaps(), (e: unknown) => e instanceof sdk.RateLimited && e.retryAfterS === 120);
    assert.equal(calls.length, 1);
    assert.ok(Date.now() - t0 < 1000);
  });

  it("other 4xx and 5xx are never retried", async () => {
    for (const status of [400, 404, 409, 422, 500]) {
      const { client, calls } = mocked(() => problem(status, "x"));
      await assert.rejects(client.listMaps(), ApiError);
      assert.equal(calls.length, 1, `status ${status}`);
    }
  });

  it("network failures: idempotent calls retried, writes not (unless the connection was refused)", async () => {
    const failing = () => {
      throw new TypeError("fetch failed");
    };
    let m = mocked(failing);
    await assert.rejects(m.client.localize("chess", demo), (e: unknown) => e instanceof TransportError && e.attempts === 4);
    assert.equal(m.calls.length, 4);
    m = mocked(failing);
    await assert.rejects(m.client.createMap({ map_id: "x" }), (e: unknown) => e instanceof TransportError && e.attempts === 1);
    assert.equal(m.calls.length, 1);
    const refused = () => {
      throw new TypeError("fetch failed", { cause: Object.assign(new Error("connect ECONNREFUSED"), { code: "ECONNREFUSED" }) });
    };
    m = mocked(refused);
    await assert.rejects(m.client.createMap({ map_id: "x" }), (e: unknown) => e instanceof TransportError && /ECONNREFUSED/.test(e.message));
    assert.equal(m.calls.length, 4);
  });

  it("backoff is exponential with jitter, capped", () => {
    const p = new RetryPolicy({ initialBackoffMs: 200, multiplier: 2, maxBackoffMs: 500, jitter: 0.5, random: () => 1 - 1e-12 });
    assert.ok(Math.abs(p.backoffMs(1) - 100) < 1e-6 && Math.abs(p.backoffMs(2) - 200) < 1e-6 && Math.abs(p.backoffMs(5) - 250) < 1e-6);
    const q = new RetryPolicy({ random: () => 0 });
    assert.equal(q.backoffMs(1), 200);
    assert.equal(q.delayForResponseMs(503, "2", 1), 2000);
    assert.equal(q.delayForResponseMs(404, null, 1), null);
    assert.throws(() => new RetryPolicy({ maxAttempts: 0 }), /maxAttempts/);
  });

  it("Retry-After: seconds or an HTTP date", () => {
    assert.equal(parseRetryAfter("3"), 3);
    assert.equal(parseRetryAfter("1.5"), 1.5);
    assert.equal(parseRetryAfter("-4"), 0);
    assert.equal(parseRetryAfter(null), null);
    assert.equal(parseRetryAfter("soon"), null);
    const now = Date.parse("Wed, 21 Oct 2015 07:28:00 GMT");
    assert.equal(parseRetryAfter("Wed, 21 Oct 2015 07:28:10 GMT", now), 10);
  });
});

describe("timeouts and cancellation", () => {
  const hanging: Handler = (_u, init) =>
    new Promise<Response>((_resolve, reject) => {
      init.signal?.addEventListener("abort", () => reject(init.signal?.reason ?? new Error("aborted")));
    });

  it("an attempt longer than timeoutMs is a TimeoutError (retried for idempotent calls)", async () => {
    const { client, calls } = mocked(hanging, { timeoutMs: 50, retry: { maxAttempts: 2 } });
    await assert.rejects(client.localize("chess", demo), (e: unknown) => e instanceof TimeoutError && e.attempts === 2);
    assert.equal(calls.length, 2);
    const w = mocked(hanging, { timeoutMs: 50 });
    await assert.rejects(w.client.deleteMap("x", { timeoutMs: 30 }), (e: unknown) => e instanceof TimeoutError && e.attempts === 1);
  });

  it("an AbortSignal cancels the call and its retries with the signal's reason", async () => {
    const { client } = mocked(hanging);
    const controller = new AbortController();
    const pending = client.localize("chess", demo, { signal: controller.signal });
    setTimeout(() => controller.abort(), 30);
    await assert.rejects(pending, (e: unknown) => e instanceof Error && e.name === "AbortError");
    const waiting = mocked(() => problem(503, "busy", {}, { "retry-after": "5" }));
    const c2 = new AbortController();
    const t0 = Date.now();
    const p2 = waiting.client.listMaps({ signal: c2.signal });
    setTimeout(() => c2.abort(new Error("user left")), 50);
    await assert.rejects(p2, /user left/);
    assert.ok(Date.now() - t0 < 2000, "the Retry-After wait was cancelled");
    const pre = new AbortController();
    pre.abort();
    await assert.rejects(client.listMaps({ signal: pre.signal }), (e: unknown) => e instanceof Error && e.name === "AbortError");
  });
});

describe("requests", () => {
  it("sends JSON with the key, the version and the etag", async () => {
    const { client, calls } = mocked(
      (url) => (url.includes("/localize") ? ok({ localized: false, map_id: "chess", map_version: 1 }) : ok({ map_id: "m", version: 2, content_hash: "h", map: {} }, { etag: '"h"' })),
      { apiKey: "k-123" },
    );
    await client.localize("chess", demo, { mapVersion: 1 });
    assert.equal(calls[0].url, "http://quadloc.test/v1/maps/chess/localize?version=1");
    const h = new Headers(calls[0].init.headers);
    assert.equal(h.get("authorization"), "Bearer k-123");
    assert.equal(h.get("content-type"), "application/json");
    assert.deepEqual(JSON.parse(String(calls[0].init.body)), demo);
    const rec = await client.updateMap("my map/1", { a: 1 }, { ifMatch: "h" });
    assert.equal(rec.etag, '"h"');
    assert.equal(calls[1].url, "http://quadloc.test/v1/maps/my%20map%2F1");
    assert.equal(new Headers(calls[1].init.headers).get("if-match"), '"h"');
    const x = mocked(() => ok({ maps: [] }), { apiKey: "k", apiKeyHeader: "x-api-key" });
    await x.client.listMaps();
    assert.equal(new Headers(x.calls[0].init.headers).get("x-api-key"), "k");
  });

  it("refuses what JSON would silently change, naming the field; nothing is sent", async () => {
    const { client, calls } = mocked(() => ok({}));
    const bad = structuredClone(demo);
    bad.detections[2].ellipse.a = Number.NaN;
    await assert.rejects(client.localize("chess", bad), (e: unknown) => e instanceof InvalidArgumentError && e.field === "request.detections[2].ellipse.a");
    await assert.rejects(client.getMap("chess", { version: 0 }), (e: unknown) => e instanceof InvalidArgumentError && e.field === "version");
    await assert.rejects(client.localize("", demo), (e: unknown) => e instanceof InvalidArgumentError && e.field === "mapId");
    await assert.rejects(client.updateMap("m", {}, { ifMatch: "" }), (e: unknown) => e instanceof InvalidArgumentError && e.field === "ifMatch");
    assert.equal(calls.length, 0);
    assert.throws(() => new QuadLocClient({ baseUrl: "ftp://x" }), /baseUrl/);
  });
});
