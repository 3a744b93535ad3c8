// Against live QuadLoc servers started by the caller (tests/e2e/test_sdk_typescript.py):
//   QUADLOC_URL          an open server with the demo map "chess"
//   QUADLOC_KEYED_URL    a server with API keys (QUADLOC_KEY_RW: read+write, QUADLOC_KEY_READ:
//                        read), QUADLOC_MAX_SESSIONS=1 and a small QUADLOC_MAX_BODY_BYTES
// Skipped (with the reason) when they are not set.
import assert from "node:assert/strict";
import { after, before, describe, it } from "node:test";
import * as sdk from "../dist/index.js";
import {
  ApiError,
  BuildFailedError,
  invertPose,
  odomFromCameraFromXRView,
  poseMatrix,
  QuadLocClient,
  transformPoint,
  worldFromCameraOpencvToOpengl,
  xrMatrixFromPose,
  type BuildJob,
  type LocalizeRequest,
  type Mat4,
  type SessionFrame,
} from "../dist/index.js";
import { readJson } from "./support.js";

const URL_ = process.env.QUADLOC_URL;
const KEYED = process.env.QUADLOC_KEYED_URL;
const KEY_RW = process.env.QUADLOC_KEY_RW ?? "";
const KEY_READ = process.env.QUADLOC_KEY_READ ?? "";
const skip = URL_ ? false : "QUADLOC_URL is not set (tests/e2e/test_sdk_typescript.py starts the servers)";
const skipKeyed = URL_ && KEYED ? false : "QUADLOC_KEYED_URL is not set";

const demo: LocalizeRequest = readJson("docs/examples/localize_chess.json");
const TRUE_CENTRE = [-0.02, -0.307, 0.77]; // docs/api.md: the demo frame's true camera centre (m)
const RUN = `ts${process.pid}`;

/** The slugs the live servers were made to answer (checked against the shared vectors below). */
const seen = new Map<string, string>();

async function expectProblem(promise: Promise<unknown>, slug: string, cls: new (...a: never[]) => ApiError, field?: string) {
  const err = await promise.then(
    () => assert.fail(`expected ${slug}, got an answer`),
    (e: unknown) => e,
  );
  assert.ok(err instanceof cls, `${slug}: got ${(err as Error)?.constructor?.name}: ${(err as Error)?.message}`);
  assert.equal(err.slug, slug, err.message);
  if (field !== undefined) assert.ok(err.fields.includes(field), `${slug}: fields ${JSON.stringify(err.fields)} lack ${field}`);
  seen.set(slug, err.constructor.name);
  return err;
}

/** A client whose fetch rewrites each request first (to make the server refuse it). */
function rewriting(rewrite: (url: string, init: RequestInit) => [string, RequestInit], retry = { maxAttempts: 1 }) {
  return new QuadLocClient({
    baseUrl: URL_,
    retry,
    fetch: ((input: string, init: RequestInit) => fetch(...rewrite(String(input), init))) as typeof fetch,
  });
}

describe("live server", { skip }, () => {
  const client = new QuadLocClient({ baseUrl: URL_ });

  it("the demo frame localizes near its true pose", async () => {
    const answer = await client.localize("chess", demo);
    assert.equal(answer.localized, true, String(answer.reason));
    assert.ok(answer.world_from_camera && answer.covariance);
    const t = answer.world_from_camera.translation_m;
    assert.ok(Math.hypot(t[0] - TRUE_CENTRE[0], t[1] - TRUE_CENTRE[1], t[2] - TRUE_CENTRE[2]) < 0.05, `centre ${t}`);
    assert.ok(answer.confidence > 0.5 && answer.confidence <= 1);
    assert.equal(answer.map_id, "chess");
    assert.deepEqual(answer.world_from_camera.matrix_column_major, sdk.columnMajorFromMatrix(answer.world_from_camera.matrix));
    // OpenGL axes, asked of the server, equal the local conversion
    const gl = await client.localize("chess", { ...demo, options: { ...demo.options, output_convention: "opengl" } });
    assert.equal(gl.world_from_camera?.convention, "opengl");
    const local = worldFromCameraOpencvToOpengl(poseMatrix(answer.world_from_camera));
    (gl.world_from_camera!.matrix as number[][]).forEach((row, r) => row.forEach((v, c) => assert.ok(Math.abs(v - local[r][c]) < 1e-6)));
  });

  it("a batch answers in order", async () => {
    const batch = await client.localizeBatch("chess", [{ ...demo, frame_id: "a" }, { ...demo, frame_id: "b" }]);
    assert.deepEqual(batch.results.map((r) => [r.frame_id, r.localized]), [["a", true], ["b", true]]);
  });

  it("maps: import, get, versions, update with the etag, export, delete", async () => {
    const office = readJson("docs/examples/office_map.json");
    const mapId = `office-${RUN}`;
    const created = await client.createMap({ ...office, map_id: mapId });
    assert.equal(created.version, 1);
    assert.equal(created.etag, `"${created.content_hash}"`);
    assert.ok((await client.listMaps()).some((m) => m.map_id === mapId));
    const latest = await client.getMap(mapId);
    const updated = await client.updateMap(mapId, { ...latest.map, name: "Office, 3rd floor" }, { ifMatch: latest.etag! });
    assert.equal(updated.version, 2);
    assert.deepEqual((await client.listVersions(mapId)).map((v) => v.version), [1, 2]);
    assert.equal((await client.exportMap(mapId)).name, "Office, 3rd floor");
    assert.equal((await client.exportMap(mapId, { version: 1 })).name, office.name);
    await expectProblem(client.updateMap(mapId, latest.map, { ifMatch: latest.etag! }), "precondition-failed", sdk.PreconditionFailed);
    await expectProblem(client.createMap({ ...office, map_id: mapId }), "map-exists", sdk.Conflict);
    await client.deleteMap(mapId);
    await expectProblem(client.getMap(mapId), "map-not-found", sdk.NotFound);
    const chess = readJson("tests/support/data/chess_scene.json");
    const copy = await client.importChessMap(chess, { mapId: `chess-${RUN}`, name: "Chess copy" });
    assert.equal(copy.map.name, "Chess copy");
    await client.deleteMap(`chess-${RUN}`);
  });

  it("a tracking session tracks the shipped recording (WebXR-style odometry, OpenGL axes)", async () => {
    const rec = readJson("docs/examples/track_chess.json");
    assert.equal(rec.convention, "opencv");
    const session = await client.startSession("chess", { camera: rec.camera, convention: "opengl" });
    assert.equal(session.info.state, "initializing");
    let tracking = 0;
    let within = 0;
    let last: Mat4 | null = null;
    for (const [i, f] of (rec.frames as (SessionFrame & { odom_from_camera: { matrix: Mat4 } })[]).entries()) {
      // what a WebXR app has: the view's transform, column-major float32, OpenGL camera axes
      const view = { transform: { matrix: xrMatrixFromPose(worldFromCameraOpencvToOpengl(f.odom_from_camera.matrix)) } };
      const r = await session.addFrame({ ...f, odom_from_camera: odomFromCameraFromXRView(view) });
      assert.equal(r.frame_index, i);
      if (r.state === "tracking") {
        tracking++;
        const truth: Mat4 = rec.ground_truth_world_from_camera[i];
        const t = r.world_from_camera!.translation_m;
        if (Math.hypot(t[0] - truth[0][3], t[1] - truth[1][3], t[2] - truth[2][3]) < 0.1) within++;
        last = poseMatrix(r.world_from_odom!);
      }
    }
    assert.ok(tracking >= 60, `tracking on ${tracking} of ${rec.frames.length} frames`);
    assert.ok(within >= 0.9 * tracking, `${within} of ${tracking} tracking frames within 10 cm`);
    // world_from_odom maps the odometry trajectory onto the map: the last frame's camera centre
    const lastFrame = rec.frames.length - 1;
    const odomCentre = rec.frames[lastFrame].odom_from_camera.matrix.map((row: number[]) => row[3]).slice(0, 3);
    const truthCentre = rec.ground_truth_world_from_camera[lastFrame].map((row: number[]) => row[3]).slice(0, 3);
    const mapped = transformPoint(last!, odomCentre);
    assert.ok(Math.hypot(...mapped.map((v, k) => v - truthCentre[k])) < 0.1, `last centre ${mapped} vs ${truthCentre}`);
    assert.ok(invertPose(last!));
    const info = await session.get();
    assert.equal(info.frames, rec.frames.length);
    assert.equal(info.state, "tracking");
    await session.close();
    await expectProblem(client.getSession(session.sessionId), "session-not-found", sdk.NotFound);
  });

  it("a map build job completes, reporting progress", async () => {
    const recording = readJson("sdk/test-vectors/build_recording.json");
    const mapId = `built-${RUN}`;
    const progress: BuildJob[] = [];
    const job = await client.buildMap(recording, { mapId, onProgress: (j) => progress.push(j), pollIntervalMs: 200, waitTimeoutMs: 180000 });
    assert.equal(job.status, "succeeded");
    assert.equal(job.map_version, 1);
    assert.equal(job.percent, 100);
    assert.ok(progress.length >= 2 && progress[0].status === "queued" || progress[0].status === "running", JSON.stringify(progress[0]));
    assert.ok(progress.every((p, k) => k === 0 || p.percent >= progress[k - 1].percent), "progress never goes back");
    const built = await client.getMap(mapId);
    assert.equal((built.map.objects as unknown[]).length, 3);
    // a second build of an existing map without If-Match is refused; with it, version 2
    await expectProblem(client.buildMap(recording, { mapId }), "precondition-required", sdk.PreconditionRequired, "header.if-match");
    const again = await client.buildMap(recording, { mapId, ifMatch: built.etag!, wait: false });
    assert.ok(["queued", "running", "succeeded"].includes(again.status));
    const polled = await client.getBuildJob(again.job_id);
    assert.equal(polled.job_id, again.job_id);
    // a recording of nothing buildable ends failed: BuildFailedError with the job's reason
    const empty = { ...recording, frames: recording.frames.map((f: { detections: unknown[] }) => ({ ...f, detections: [] })) };
    await assert.rejects(client.buildMap(empty, { mapId: `empty-${RUN}`, pollIntervalMs: 200 }), (e: unknown) => e instanceof BuildFailedError && e.job.status === "failed" && typeof e.job.error?.reason === "string");
    while (!["succeeded", "failed"].includes((await client.getBuildJob(again.job_id)).status)) await sdk.sleep(200);
    await client.deleteMap(mapId);
  });

  it("a map built from the shipped recording is calibrated and read back", async () => {
    const recording = readJson("docs/examples/room_recording.json.gz");
    const mapId = `calibrated-${RUN}`;
    await client.buildMap(recording, { mapId, pollIntervalMs: 200, waitTimeoutMs: 180000 });
    await expectProblem(client.getCalibration(mapId), "not-found", sdk.NotFound);
    const cal = await client.calibrateMap(mapId, recording, { timeoutMs: 300000 });
    const heldOut = recording.frames.filter((_: unknown, i: number) => (i + 1) % recording.holdout_every === 0).length;
    assert.equal(cal.map_version, 1);
    assert.equal(cal.fit_frames, heldOut);
    assert.equal(cal.after.frames, heldOut);
    assert.ok(cal.covariance_scale > 0 && typeof cal.after.mean_nees === "number");
    assert.deepEqual(await client.getCalibration(mapId), cal);
    await client.deleteMap(mapId);
  });

  it("request errors are typed problem documents naming the field", async () => {
    const bad = structuredClone(demo);
    bad.camera.fx = -1;
    await expectProblem(client.localize("chess", bad), "validation-error", sdk.ValidationError, "camera.fx");
    const det = structuredClone(demo);
    (det.detections[2] as Record<string, unknown>).sigmaa = 1;
    await expectProblem(client.localize("chess", det), "validation-error", sdk.ValidationError, "detections[2].sigmaa");
    const prior = { ...demo, prior: { world_from_camera: { quaternion_wxyz: [2, 0, 0, 0], translation_m: [0, 0, 0] } } };
    await expectProblem(client.localize("chess", prior), "invalid-geometry", sdk.ValidationError);
    await expectProblem(client.createMap({ map_id: `bad-${RUN}`, name: "x", categories: ["a"], objects: [{ object_id: "o", category: "b", center: [0, 0, 0], axes: [1, 1, 1] }] }), "invalid-map", sdk.ValidationError, "objects[0].category");
    await expectProblem(client.localize("nope-" + RUN, demo), "map-not-found", sdk.NotFound);
    await expectProblem(client.deleteMap("chess"), "default-map", sdk.Conflict);
    await expectProblem(client.getMap("chess", { version: 999 }), "map-not-found", sdk.NotFound);
    // what the client never sends, made by rewriting its requests on the way out
    await expectProblem(rewriting((u, i) => [u, { ...i, body: "{not json" }]).localize("chess", demo), "malformed-json", sdk.ValidationError);
    await expectProblem(rewriting((u, i) => [u, { ...i, headers: { Accept: "application/json" } }]).localize("chess", demo), "unsupported-media-type", sdk.ClientError);
    await expectProblem(rewriting((u, i) => [u, { ...i, method: "PATCH" }]).listMaps(), "method-not-allowed", sdk.ClientError);
    await expectProblem(rewriting((u, i) => [u.replace("/v1/maps", "/v1/mapz"), i]).listMaps(), "not-found", sdk.NotFound);
    const latest = await client.getMap("chess");
    await expectProblem(rewriting((u, i) => [u, { ...i, headers: { "Content-Type": "application/json" } }]).updateMap("chess", latest.map, { ifMatch: latest.etag! }), "precondition-required", sdk.PreconditionRequired, "header.if-match");
  });
});

describe("live server with API keys and small limits", { skip: skipKeyed }, () => {
  const rw = new QuadLocClient({ baseUrl: KEYED, apiKey: KEY_RW });
  const read = new QuadLocClient({ baseUrl: KEYED, apiKey: KEY_READ, apiKeyHeader: "x-api-key" });
  const anonymous = new QuadLocClient({ baseUrl: KEYED });
  const sessions: sdk.TrackingSession[] = [];
  const rec = readJson("docs/examples/track_chess.json");

  before(async () => {
    assert.equal((await rw.healthz()).status, "ok");
  });
  after(async () => {
    for (const s of sessions) await s.close().catch(() => undefined);
  });

  it("keys: none is 401, a read key cannot write (403), read+write can", async () => {
    await expectProblem(anonymous.listMaps(), "unauthorized", sdk.Unauthorized);
    assert.ok((await read.listMaps()).some((m) => m.map_id === "chess"));
    assert.equal((await read.localize("chess", demo)).localized, true);
    const office = readJson("docs/examples/office_map.json");
    await expectProblem(read.createMap({ ...office, map_id: `o-${RUN}` }), "forbidden", sdk.Forbidden);
    await rw.createMap({ ...office, map_id: `o-${RUN}` });
    await rw.deleteMap(`o-${RUN}`);
  });

  it("a body over the server's limit is PayloadTooLarge", async () => {
    const frames = Array.from({ length: 30 }, (_, k) => ({ ...demo, frame_id: `f${k}` }));
    await expectProblem(rw.localizeBatch("chess", frames), "payload-too-large", sdk.PayloadTooLarge);
  });

  it("a full replica answers session-capacity (503 with Retry-After) once the retries are spent", async () => {
    sessions.push(await rw.startSession("chess", { camera: rec.camera }));
    // the server asks for Retry-After: 30 s, more than this client waits: thrown at once
    const impatient = new QuadLocClient({ baseUrl: KEYED, apiKey: KEY_RW, retry: { maxRetryAfterMs: 10000 } });
    const t0 = Date.now();
    const err = await expectProblem(impatient.startSession("chess", { camera: rec.camera }), "session-capacity", sdk.ServiceUnavailable);
    assert.equal(err.attempts, 1);
    assert.equal(err.retryAfterS, 30);
    assert.ok(Date.now() - t0 < 5000);
  });

  it("every documented problem the servers can be made to answer was answered with its class", () => {
    const vectors: { slug: string; error: string }[] = readJson("sdk/test-vectors/problems.json").problems;
    for (const [slug, cls] of seen) {
      const v = vectors.find((p) => p.slug === slug);
      assert.ok(v, `the server answered ${slug}, which sdk/test-vectors/problems.json lacks`);
      assert.equal(cls, v.error, slug);
    }
    // the rest (bad-request, not-acceptable, version-conflict, busy, database-unavailable,
    // map-loading, not-ready, internal-error) need a failing or racing server:
    // test/client.test.ts maps every type through a mocked fetch
    assert.ok(seen.size >= 17, `only ${seen.size} live: ${[...seen.keys()]}`);
  });
});
