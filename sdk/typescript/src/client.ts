/**
 * `QuadLocClient`: the HTTP client of the QuadLoc API on `fetch` (browsers, WebXR pages, Node
 * >= 18, React Native), with retries on 429 / 503 honouring `Retry-After`, a timeout per
 * attempt, cancellation through `AbortSignal`, and typed errors carrying the problem document.
 *
 *     const client = new QuadLocClient({ baseUrl: "http://127.0.0.1:8000" });
 *     const answer = await client.localize("chess", request);
 *     if (answer.localized) use(answer.world_from_camera);   // row-major matrix, metres
 *
 * "Not localized" is a normal answer (`answer.localized === false`, `answer.reason`); errors
 * are thrown as `ApiError` subclasses (errors.ts).
 */
import {
  errorFromResponse,
  QuadLocError,
  TimeoutError,
  TransportError,
} from "./errors.js";
import type {
  BatchLocalizeResponse,
  BuildJob,
  Calibration,
  Health,
  LocalizeRequest,
  LocalizeResponse,
  MapDocument,
  MapRecord,
  MapSummary,
  MapVersion,
  SessionCreate,
  SessionFrame,
  SessionFrameResult,
  SessionInfo,
} from "./models.js";
import { RetryPolicy, sleep, type RetryOptions } from "./retry.js";

export const SDK_VERSION = "0.1.0";
export const DEFAULT_BASE_URL = "http://127.0.0.1:8000";

/** How the client is set up. */
export interface ClientOptions {
  /** The server, e.g. "http://127.0.0.1:8000" (default) or "https://quadloc.example". */
  baseUrl?: string;
  /** API key (scope read, or read+write); none for an open loopback server. */
  apiKey?: string | null;
  /** Header carrying the key: "authorization" (`Bearer <key>`, default) or "x-api-key". */
  apiKeyHeader?: "authorization" | "x-api-key";
  /** Timeout of one attempt, ms (connection, request and the whole answer). Default 30000. */
  timeoutMs?: number;
  /** Retry policy (see retry.ts); `{ maxAttempts: 1 }` never retries. */
  retry?: RetryOptions | RetryPolicy;
  /** The fetch to use (default the global one): a mock in tests, a polyfill elsewhere. */
  fetch?: typeof fetch;
}

/** Per-call options. */
export interface CallOptions {
  /** Cancels the call (and its retries); the promise rejects with the signal's reason. */
  signal?: AbortSignal;
  /** Timeout of one attempt of this call, ms (default: the client's). */
  timeoutMs?: number;
}

/** Bad arguments caught before anything is sent; `field` names the argument. */
export class InvalidArgumentError extends QuadLocError {
  readonly field: string;
  constructor(field: string, message: string) {
    super(`${field}: ${message}`);
    this.field = field;
  }
}

/** A build job that ended `failed` (`job.error.reason`), or did not end in time. */
export class BuildFailedError extends QuadLocError {
  readonly job: BuildJob;
  constructor(message: string, job: BuildJob) {
    super(message);
    this.job = job;
  }
}

interface Call {
  method: "GET" | "POST" | "PUT" | "DELETE";
  path: string;
  query?: Record<string, string | number | undefined>;
  body?: string;
  headers?: Record<string, string>;
  /** May be replayed after a failure that may have reached the server. */
  idempotent: boolean;
}

/** What one exchange returned. */
interface Answer {
  status: number;
  headers: Headers;
  text: string;
  url: string;
  method: string;
}

const NOT_SENT_CODES = new Set(["ECONNREFUSED", "ENOTFOUND", "EAI_AGAIN", "UND_ERR_CONNECT_TIMEOUT"]);

function segment(field: string, value: string): string {
  if (typeof value !== "string" || value === "") {
    throw new InvalidArgumentError(field, `must be a non-empty string, got ${JSON.stringify(value)}`);
  }
  return encodeURIComponent(value);
}

function positiveInteger(field: string, value: number | undefined): number | undefined {
  if (value === undefined) return undefined;
  if (!Number.isInteger(value) || value < 1) {
    throw new InvalidArgumentError(field, `must be an integer >= 1, got ${String(value)}`);
  }
  return value;
}

/**
 * JSON text of a request body. Refuses what JSON.stringify would silently change: NaN and
 * infinities (it writes null) and undefined array entries, naming the path of the value.
 */
export function jsonBody(field: string, value: unknown): string {
  const walk = (v: unknown, path: string): void => {
    if (typeof v === "number") {
      if (!Number.isFinite(v)) throw new InvalidArgumentError(path, `must be a finite number, got ${v}`);
    } else if (Array.isArray(v)) {
      v.forEach((x, i) => {
        if (x === undefined) throw new InvalidArgumentError(`${path}[${i}]`, "is undefined");
        walk(x, `${path}[${i}]`);
      });
    } else if (ArrayBuffer.isView(v)) {
      Array.from(v as unknown as ArrayLike<number>).forEach((x, i) => walk(x, `${path}[${i}]`));
    } else if (v && typeof v === "object") {
      for (const [k, x] of Object.entries(v)) walk(x, path ? `${path}.${k}` : k);
    } else if (typeof v === "bigint" || typeof v === "function" || typeof v === "symbol") {
      throw new InvalidArgumentError(path, `is not JSON (${typeof v})`);
    }
  };
  walk(value, field);
  return JSON.stringify(value, (_k, v: unknown) => (ArrayBuffer.isView(v) ? Array.from(v as unknown as ArrayLike<number>) : v));
}

function etagValue(etag: string): string {
  const e = etag.trim();
  return e.startsWith('"') || e.startsWith('W/"') ? e : `"${e}"`;
}

/** The QuadLoc client (one per server; safe to share; no state but its settings). */
export class QuadLocClient {
  readonly baseUrl: string;
  readonly retry: RetryPolicy;
  readonly timeoutMs: number;
  private readonly fetchImpl: typeof fetch;
  private readonly headers: Record<string, string>;

  constructor(options: ClientOptions = {}) {
    const baseUrl = options.baseUrl ?? DEFAULT_BASE_URL;
    if (typeof baseUrl !== "string" || !/^https?:\/\//.test(baseUrl)) {
      throw new InvalidArgumentError("baseUrl", `must start with http:// or https://, got ${JSON.stringify(baseUrl)}`);
    }
    this.baseUrl = baseUrl.replace(/\/+$/, "");
    this.retry = options.retry instanceof RetryPolicy ? options.retry : new RetryPolicy(options.retry);
    this.timeoutMs = options.timeoutMs ?? 30000;
    if (!(this.timeoutMs > 0)) throw new InvalidArgumentError("timeoutMs", `must be > 0, got ${this.timeoutMs}`);
    const f = options.fetch ?? globalThis.fetch;
    if (typeof f !== "function") throw new InvalidArgumentError("fetch", "no fetch available: pass one");
    this.fetchImpl = f.bind(globalThis);
    this.headers = { Accept: "application/json, application/problem+json" };
    if (options.apiKey != null) {
      if (typeof options.apiKey !== "string" || !options.apiKey.trim()) {
        throw new InvalidArgumentError("apiKey", "must be a non-empty string or null");
      }
      if ((options.apiKeyHeader ?? "authorization") === "authorization") {
        this.headers.Authorization = `Bearer ${options.apiKey.trim()}`;
      } else {
        this.headers["X-API-Key"] = options.apiKey.trim();
      }
    }
  }

  // ----------------------------------------------------------------------------- transport

  private url(call: Call): string {
    let url = this.baseUrl + call.path;
    const q = Object.entries(call.query ?? {}).filter(([, v]) => v !== undefined);
    if (q.length) url += "?" + new URLSearchParams(q.map(([k, v]) => [k, String(v)])).toString();
    return url;
  }

  /** One call with its retries; resolves with a status < 400, throws otherwise. */
  private async send(call: Call, options: CallOptions = {}): Promise<Answer> {
    const url = this.url(call);
    const userSignal = options.signal;
    const timeoutMs = options.timeoutMs ?? this.timeoutMs;
    const headers: Record<string, string> = { ...this.headers, ...call.headers };
    if (call.body !== undefined) headers["Content-Type"] = "application/json";
    for (let attempt = 1; ; attempt++) {
      if (userSignal?.aborted) throw userSignal.reason;
      const controller = new AbortController();
      let timedOut = false;
      const timer = setTimeout(() => {
        timedOut = true;
        controller.abort();
      }, timeoutMs);
      const onAbort = () => controller.abort(userSignal?.reason);
      userSignal?.addEventListener("abort", onAbort, { once: true });
      let answer: Answer;
      try {
        const response = await this.fetchImpl(url, {
          method: call.method,
          headers,
          body: call.body,
          signal: controller.signal,
        });
        const text = await response.text();
        answer = { status: response.status, headers: response.headers, text, url, method: call.method };
      } catch (err) {
        if (userSignal?.aborted) throw userSignal.reason;
        const code = networkErrorCode(err);
        const retryable = attempt < this.retry.maxAttempts && (call.idempotent || (!timedOut && NOT_SENT_CODES.has(code)));
        if (retryable) {
          await sleep(this.retry.backoffMs(attempt), userSignal);
          continue;
        }
        const init = { method: call.method, url, attempts: attempt, cause: err };
        if (timedOut) throw new TimeoutError(`no answer within ${timeoutMs} ms`, init);
        throw new TransportError(describeNetworkError(err), init);
      } finally {
        clearTimeout(timer);
        userSignal?.removeEventListener("abort", onAbort);
      }
      if (answer.status < 400) return answer;
      if (attempt < this.retry.maxAttempts) {
        const delay = this.retry.delayForResponseMs(answer.status, answer.headers.get("retry-after"), attempt);
        if (delay !== null) {
          await sleep(delay, userSignal);
          continue;
        }
      }
      throw errorFromResponse({ ...answer, attempts: attempt });
    }
  }

  private static json<T>(answer: Answer): T {
    try {
      return JSON.parse(answer.text) as T;
    } catch (err) {
      throw new QuadLocError(`${answer.method} ${answer.url}: the server answered ${answer.status} with a body that is not JSON`, { cause: err });
    }
  }

  private async getJson<T>(path: string, options?: CallOptions, query?: Call["query"]): Promise<T> {
    return QuadLocClient.json<T>(await this.send({ method: "GET", path, query, idempotent: true }, options));
  }

  private static record(answer: Answer): MapRecord {
    const data = QuadLocClient.json<Omit<MapRecord, "etag">>(answer);
    return { ...data, etag: answer.headers.get("etag") };
  }

  private mapPath(mapId: string): string {
    return `/v1/maps/${segment("mapId", mapId)}`;
  }

  // ----------------------------------------------------------------------------- service

  /** `GET /healthz`: the process is alive. */
  healthz(options?: CallOptions): Promise<Health> {
    return this.getJson<Health>("/healthz", options);
  }

  /** `GET /readyz`: database reachable and default map loadable (503: ServiceUnavailable). */
  readyz(options?: CallOptions): Promise<Health> {
    return this.getJson<Health>("/readyz", options);
  }

  /** `GET /metrics`: the Prometheus text exposition. */
  async metrics(options?: CallOptions): Promise<string> {
    return (await this.send({ method: "GET", path: "/metrics", idempotent: true }, options)).text;
  }

  // ----------------------------------------------------------------------------- maps

  /** Every map with its latest version (`GET /v1/maps`). */
  async listMaps(options?: CallOptions): Promise<MapSummary[]> {
    return (await this.getJson<{ maps: MapSummary[] }>("/v1/maps", options)).maps;
  }

  /** The latest (or the given) version of a map, with its `etag` (`GET /v1/maps/{id}`). */
  async getMap(mapId: string, options: CallOptions & { version?: number } = {}): Promise<MapRecord> {
    const version = positiveInteger("version", options.version);
    return QuadLocClient.record(
      await this.send({ method: "GET", path: this.mapPath(mapId), query: { version }, idempotent: true }, options),
    );
  }

  /** The map document of the latest (or the given) version: what `createMap` imports. */
  async exportMap(mapId: string, options: CallOptions & { version?: number } = {}): Promise<MapDocument> {
    return (await this.getMap(mapId, options)).map;
  }

  /** Every stored version of a map, ascending (`GET /v1/maps/{id}/versions`). */
  async listVersions(mapId: string, options?: CallOptions): Promise<MapVersion[]> {
    return (await this.getJson<{ versions: MapVersion[] }>(`${this.mapPath(mapId)}/versions`, options)).versions;
  }

  /**
   * Imports a map document (docs/maps.md) as a new map, version 1 (`POST /v1/maps`).
   * `Conflict` (map-exists) when the id is taken; `ValidationError` (invalid-map) naming fields.
   */
  async createMap(document: MapDocument, options?: CallOptions): Promise<MapRecord> {
    const body = jsonBody("map", document);
    return QuadLocClient.record(await this.send({ method: "POST", path: "/v1/maps", body, idempotent: false }, options));
  }

  /** Creates map `mapId` from the 7-Scenes Chess format (`POST /v1/maps:import-chess`). */
  async importChessMap(
    chess: Record<string, unknown>,
    init: CallOptions & { mapId: string; name?: string },
  ): Promise<MapRecord> {
    segment("mapId", init.mapId);
    const body = jsonBody("chess", chess);
    const call: Call = {
      method: "POST", path: "/v1/maps:import-chess", query: { map_id: init.mapId, name: init.name }, body, idempotent: false,
    };
    return QuadLocClient.record(await this.send(call, init));
  }

  /**
   * Replaces a map by a new version n + 1 (`PUT /v1/maps/{id}`). `ifMatch`: the `etag` of the
   * version you edited (`getMap`); stale: `PreconditionFailed`. Retried on 429 / 503 only: the
   * PUT is conditional, so a replay after a write that landed fails instead of overwriting.
   */
  async updateMap(mapId: string, document: MapDocument, init: CallOptions & { ifMatch: string }): Promise<MapRecord> {
    if (typeof init?.ifMatch !== "string" || !init.ifMatch.trim()) {
      throw new InvalidArgumentError("ifMatch", "must be the ETag of the version edited (updates never silently overwrite)");
    }
    const body = jsonBody("map", document);
    const call: Call = {
      method: "PUT", path: this.mapPath(mapId), body, headers: { "If-Match": etagValue(init.ifMatch) }, idempotent: false,
    };
    return QuadLocClient.record(await this.send(call, init));
  }

  /** Deletes a map and all its versions (`DELETE /v1/maps/{id}`). */
  async deleteMap(mapId: string, options?: CallOptions): Promise<void> {
    await this.send({ method: "DELETE", path: this.mapPath(mapId), idempotent: false }, options);
  }

  // ----------------------------------------------------------------------------- localization

  /**
   * Localizes one frame against the latest version of `mapId` (or `mapVersion`)
   * (`POST /v1/maps/{id}/localize`). Retried on 429 / 503 and, being a pure computation, after
   * network failures and timeouts too.
   */
  async localize(
    mapId: string,
    request: LocalizeRequest,
    options: CallOptions & { mapVersion?: number } = {},
  ): Promise<LocalizeResponse> {
    const version = positiveInteger("mapVersion", options.mapVersion);
    const body = jsonBody("request", request);
    const call: Call = { method: "POST", path: `${this.mapPath(mapId)}/localize`, query: { version }, body, idempotent: true };
    return QuadLocClient.json<LocalizeResponse>(await this.send(call, options));
  }

  /** Several frames in one request, solved in order against one map version; `results` in order. */
  async localizeBatch(
    mapId: string,
    frames: LocalizeRequest[],
    options: CallOptions & { mapVersion?: number } = {},
  ): Promise<BatchLocalizeResponse> {
    if (!Array.isArray(frames) || frames.length === 0) {
      throw new InvalidArgumentError("frames", "must be a non-empty array of localize requests");
    }
    const version = positiveInteger("mapVersion", options.mapVersion);
    const body = jsonBody("frames", { frames });
    const call: Call = {
      method: "POST", path: `${this.mapPath(mapId)}/localize:batch`, query: { version }, body, idempotent: true,
    };
    return QuadLocClient.json<BatchLocalizeResponse>(await this.send(call, options));
  }

  // ----------------------------------------------------------------------------- tracking

  /**
   * Starts a tracking session on `mapId` (`POST /v1/maps/{id}/sessions`): `camera`, the camera
   * axes `convention` of every odometry pose and answer ("opengl" for WebXR / ARKit / ARCore),
   * `options`. docs/tracking.md.
   */
  async startSession(mapId: string, body: SessionCreate, options?: CallOptions): Promise<TrackingSession> {
    const call: Call = { method: "POST", path: `${this.mapPath(mapId)}/sessions`, body: jsonBody("session", body), idempotent: false };
    return new TrackingSession(this, QuadLocClient.json<SessionInfo>(await this.send(call, options)));
  }

  /** A session's state (`GET /v1/sessions/{id}`); `NotFound` (session-not-found) once expired. */
  getSession(sessionId: string, options?: CallOptions): Promise<SessionInfo> {
    return this.getJson<SessionInfo>(`/v1/sessions/${segment("sessionId", sessionId)}`, options);
  }

  /** Ends a session (`DELETE /v1/sessions/{id}`). */
  async deleteSession(sessionId: string, options?: CallOptions): Promise<void> {
    await this.send({ method: "DELETE", path: `/v1/sessions/${segment("sessionId", sessionId)}`, idempotent: false }, options);
  }

  /**
   * Sends tracking frames (`POST /v1/sessions/{id}/frames`): one frame, or a recording of up to
   * 900 in time order, validated whole before any is fused. Not replayed after a network
   * failure (a frame fused twice would count twice).
   */
  async addSessionFrames(sessionId: string, frames: SessionFrame[], options?: CallOptions): Promise<SessionFrameResult[]> {
    if (!Array.isArray(frames) || frames.length === 0) {
      throw new InvalidArgumentError("frames", "must be a non-empty array of session frames");
    }
    const body = frames.length === 1 ? jsonBody("frame", frames[0]) : jsonBody("frames", { frames });
    const call: Call = {
      method: "POST", path: `/v1/sessions/${segment("sessionId", sessionId)}/frames`, body, idempotent: false,
    };
    return QuadLocClient.json<{ results: SessionFrameResult[] }>(await this.send(call, options)).results;
  }

  // ----------------------------------------------------------------------------- map building

  /**
   * Builds a map from a recording (`POST /v1/maps:build`, docs/map_building.md): intrinsics,
   * frames with the app's `world_from_camera` (OpenCV camera axes) and detections. With
   * `wait` (default) the job is polled every `pollIntervalMs` until it ends: resolves with the
   * succeeded job (`map_version`, `report`) or rejects with `BuildFailedError` (`job.error`).
   * `onProgress(job)` runs whenever the stage, percent or object count changes. For an
   * existing map pass `ifMatch` (its `etag`). Starting a build is never replayed blindly.
   */
  async buildMap(
    recording: Record<string, unknown>,
    init: CallOptions & {
      mapId: string;
      ifMatch?: string;
      wait?: boolean;
      onProgress?: (job: BuildJob) => void;
      pollIntervalMs?: number;
      waitTimeoutMs?: number;
    },
  ): Promise<BuildJob> {
    segment("mapId", init.mapId);
    const headers: Record<string, string> = {};
    if (init.ifMatch !== undefined) headers["If-Match"] = etagValue(init.ifMatch);
    const call: Call = {
      method: "POST", path: "/v1/maps:build", query: { map_id: init.mapId }, body: jsonBody("recording", recording), headers, idempotent: false,
    };
    const answer = await this.send(call, init);
    let job = QuadLocClient.json<BuildJob>(answer);
    const location = answer.headers.get("location") ?? `/v1/build-jobs/${encodeURIComponent(job.job_id)}`;
    init.onProgress?.(job);
    if (init.wait === false) return job;
    const pollMs = init.pollIntervalMs ?? 500;
    const waitTimeoutMs = init.waitTimeoutMs ?? 600000;
    const t0 = Date.now();
    let last = `${job.stage}|${job.percent}|${job.objects_found}`;
    while (job.status !== "succeeded" && job.status !== "failed") {
      if (Date.now() - t0 > waitTimeoutMs) {
        throw new BuildFailedError(`build job ${job.job_id} not finished after ${waitTimeoutMs} ms (still ${job.status}); poll it with getBuildJob`, job);
      }
      await sleep(pollMs, init.signal);
      job = await this.getBuildJob(location, init);
      const now = `${job.stage}|${job.percent}|${job.objects_found}`;
      if (now !== last) init.onProgress?.(job);
      last = now;
    }
    if (job.status === "failed") {
      throw new BuildFailedError(`build job ${job.job_id} failed: ${String(job.error?.reason)}: ${String(job.error?.detail)}`, job);
    }
    return job;
  }

  /**
   * Fits, stores and returns a map version's own calibration (`POST
   * /v1/maps/{id}/calibration`, docs/map_building.md "Calibrating the map") from the recording
   * it was built from (with `holdout_every`). Synchronous: pass a `timeoutMs` long enough for
   * the fit (1,000 held-out frames take about 25 s). Not replayed after a network failure.
   */
  async calibrateMap(mapId: string, recording: Record<string, unknown>,
                     options: CallOptions & { version?: number } = {}): Promise<Calibration> {
    const version = positiveInteger("version", options.version);
    const call: Call = {
      method: "POST", path: `${this.mapPath(mapId)}/calibration`, query: { version },
      body: jsonBody("recording", recording), idempotent: false,
    };
    return QuadLocClient.json<Calibration>(await this.send(call, options));
  }

  /** A map version's stored calibration (`GET /v1/maps/{id}/calibration`; `NotFound`: none). */
  getCalibration(mapId: string, options: CallOptions & { version?: number } = {}): Promise<Calibration> {
    const version = positiveInteger("version", options.version);
    return this.getJson<Calibration>(`${this.mapPath(mapId)}/calibration`, options, { version });
  }

  /** A build job's state, by id or by its `Location` path (`GET /v1/build-jobs/{id}`). */
  getBuildJob(jobIdOrLocation: string, options?: CallOptions): Promise<BuildJob> {
    const path = jobIdOrLocation.startsWith("/") ? jobIdOrLocation : `/v1/build-jobs/${segment("jobId", jobIdOrLocation)}`;
    return this.getJson<BuildJob>(path, options);
  }
}

/** A live tracking session (docs/tracking.md); `info` is the server's session document. */
export class TrackingSession {
  readonly client: QuadLocClient;
  readonly sessionId: string;
  info: SessionInfo;

  constructor(client: QuadLocClient, info: SessionInfo) {
    this.client = client;
    this.info = info;
    this.sessionId = info.session_id;
  }

  /** Sends one frame; resolves with its answer (`state`, `world_from_camera`, `world_from_odom`). */
  async addFrame(frame: SessionFrame, options?: CallOptions): Promise<SessionFrameResult> {
    return (await this.client.addSessionFrames(this.sessionId, [frame], options))[0];
  }

  /** Sends recorded frames (time order, at most 900) in one request. */
  addFrames(frames: SessionFrame[], options?: CallOptions): Promise<SessionFrameResult[]> {
    return this.client.addSessionFrames(this.sessionId, frames, options);
  }

  /** The session's state on the server (and updates `info`). */
  async get(options?: CallOptions): Promise<SessionInfo> {
    this.info = await this.client.getSession(this.sessionId, options);
    return this.info;
  }

  /** Ends the session on the server. */
  close(options?: CallOptions): Promise<void> {
    return this.client.deleteSession(this.sessionId, options);
  }
}

function networkErrorCode(err: unknown): string {
  let e: unknown = err;
  for (let depth = 0; depth < 4 && e && typeof e === "object"; depth++) {
    const code = (e as { code?: unknown }).code;
    if (typeof code === "string") return code;
    e = (e as { cause?: unknown }).cause;
  }
  return "";
}

function describeNetworkError(err: unknown): string {
  const code = networkErrorCode(err);
  const msg = err instanceof Error ? err.message : String(err);
  return code ? `${msg} (${code})` : msg;
}

