/**
 * Errors of the QuadLoc client. Every error the server reports is an RFC 9457 problem document
 * `{type, title, status, detail, instance, errors: [{field, message}]}`; the client throws the
 * subclass of `ApiError` matching its HTTP status (the same mapping as the Python and C# SDKs,
 * checked against `sdk/test-vectors/problems.json`) and keeps the whole document on it.
 * A "not localized" answer is NOT an error (200 with `localized: false` and a `reason`).
 *
 *     QuadLocError
 *     ├── TransportError          no HTTP answer (network failure, timeout), after the retries
 *     │   └── TimeoutError        an attempt outlasted the client's `timeoutMs`
 *     └── ApiError                the server answered 4xx / 5xx
 *         ├── ClientError         4xx: fix the request (405, 406, 415 are plain ClientErrors)
 *         │   ├── ValidationError       400 / 422: `errors` names each field
 *         │   ├── Unauthorized          401
 *         │   ├── Forbidden             403
 *         │   ├── NotFound              404 (map, version, session, job)
 *         │   ├── Conflict              409
 *         │   │   ├── PreconditionFailed    412 (stale If-Match)
 *         │   │   └── PreconditionRequired  428 (update without If-Match)
 *         │   ├── PayloadTooLarge       413
 *         │   └── RateLimited           429 (retried; thrown when retries run out)
 *         └── ServerError         5xx
 *             └── ServiceUnavailable    503 (retried; thrown when retries run out)
 *
 * Cancellation through an `AbortSignal` rejects with the signal's reason (an `AbortError`
 * DOMException unless the caller gave another), as `fetch` does; it is not wrapped.
 */
import type { Problem, ProblemField } from "./models.js";
import { parseRetryAfter } from "./retry.js";

/** The prefix of every QuadLoc problem `type`. */
export const PROBLEM_TYPE_PREFIX = "urn:quadloc:problem:";

/** Base class of every error of the client. */
export class QuadLocError extends Error {
  constructor(message: string, options?: { cause?: unknown }) {
    super(message, options);
    this.name = new.target.name;
  }
}

/** No HTTP answer: the connection failed or an attempt timed out (after the retries allowed). */
export class TransportError extends QuadLocError {
  readonly method: string;
  readonly url: string;
  readonly attempts: number;
  constructor(message: string, init: { method: string; url: string; attempts: number; cause?: unknown }) {
    super(`${init.method} ${init.url}: ${message} (after ${init.attempts} attempt(s))`, { cause: init.cause });
    this.method = init.method;
    this.url = init.url;
    this.attempts = init.attempts;
  }
}

/** An attempt took longer than the client's (or the call's) `timeoutMs`. */
export class TimeoutError extends TransportError {}

/** What an `ApiError` is built from. */
export interface ApiErrorInit {
  status: number;
  method: string;
  url: string;
  /** The parsed problem document, or null when the body was not problem JSON. */
  problem: Problem | null;
  /** The raw body (e.g. a proxy's HTML error page). */
  text?: string;
  headers?: Headers;
  attempts?: number;
}

/** The server answered with an error status; the problem document's members are properties. */
export class ApiError extends QuadLocError {
  readonly status: number;
  /** The problem type, `urn:quadloc:problem:<slug>` (or "about:blank"). */
  readonly type: string;
  /** The slug of `type` (`validation-error`, `map-not-found`, ...), or null for another URI. */
  readonly slug: string | null;
  readonly title: string;
  readonly detail: string | null;
  readonly instance: string | null;
  /** The invalid fields (`detections[2].ellipse.a`, `query.version`, `header.if-match`, ...). */
  readonly errors: ProblemField[];
  /** The problem document as received ({} when the body was not problem JSON). */
  readonly problem: Partial<Problem> & Record<string, unknown>;
  readonly method: string;
  readonly url: string;
  readonly headers: Headers;
  readonly attempts: number;
  readonly text: string;

  constructor(init: ApiErrorInit) {
    const problem = (init.problem ?? {}) as Partial<Problem> & Record<string, unknown>;
    const type = typeof problem.type === "string" ? problem.type : "about:blank";
    const title = typeof problem.title === "string" && problem.title ? problem.title : `HTTP ${init.status}`;
    const detail = problem.detail != null ? String(problem.detail) : null;
    const errors = fieldErrors(problem.errors);
    let message = `${init.status} ${title}`;
    if (detail) message += `: ${detail}`;
    if (errors.length) {
      message += ` [${errors.slice(0, 10).map((e) => `${e.field}: ${e.message}`).join("; ")}`;
      message += errors.length > 10 ? `; ... ${errors.length - 10} more]` : "]";
    }
    if (!init.problem && init.text) message += `: ${init.text.slice(0, 200)}`;
    super(`${message} (${init.method} ${init.url})`);
    this.status = init.status;
    this.type = type;
    this.slug = type.startsWith(PROBLEM_TYPE_PREFIX) ? type.slice(PROBLEM_TYPE_PREFIX.length) : null;
    this.title = title;
    this.detail = detail;
    this.instance = typeof problem.instance === "string" ? problem.instance : null;
    this.errors = errors;
    this.problem = problem;
    this.method = init.method;
    this.url = init.url;
    this.headers = init.headers ?? new Headers();
    this.attempts = init.attempts ?? 1;
    this.text = init.text ?? "";
  }

  /** The names of the invalid fields (possibly empty). */
  get fields(): string[] {
    return this.errors.map((e) => e.field);
  }

  /** Seconds the server asked to wait (`Retry-After`), or null. */
  get retryAfterS(): number | null {
    return parseRetryAfter(this.headers.get("retry-after"));
  }
}

/** 4xx: the request is wrong; sending it again unchanged fails again (except 429). */
export class ClientError extends ApiError {}
/** 400 / 422: the request failed validation; `errors` names each field. */
export class ValidationError extends ClientError {}
/** 401: no API key, or an unknown one (give `apiKey` to the client). */
export class Unauthorized extends ClientError {}
/** 403: the key lacks the scope (`read` / `write`) of this call. */
export class Forbidden extends ClientError {}
/** 404: unknown map, map version, tracking session or build job. */
export class NotFound extends ClientError {}
/** 409: the map id is taken, the default map cannot be deleted, or a concurrent update won. */
export class Conflict extends ClientError {}
/** 412: the If-Match ETag is stale: read the map again and re-apply the change. */
export class PreconditionFailed extends Conflict {}
/** 428: updates must say which version they replace (If-Match). */
export class PreconditionRequired extends Conflict {}
/** 413: the body is over the server's limit (split a batch). */
export class PayloadTooLarge extends ClientError {}
/** 429: too many requests (thrown once the retries ran out); `retryAfterS` is the advice. */
export class RateLimited extends ClientError {}
/** 5xx: the server failed; report it with `instance`. */
export class ServerError extends ApiError {}
/** 503: busy, not ready, database down, map loading (thrown once the retries ran out). */
export class ServiceUnavailable extends ServerError {}

/** HTTP status -> error class (any other 4xx: ClientError, any other 5xx: ServerError). */
export const ERROR_CLASS_BY_STATUS: Readonly<Record<number, new (init: ApiErrorInit) => ApiError>> = {
  400: ValidationError,
  401: Unauthorized,
  403: Forbidden,
  404: NotFound,
  409: Conflict,
  412: PreconditionFailed,
  413: PayloadTooLarge,
  422: ValidationError,
  428: PreconditionRequired,
  429: RateLimited,
  503: ServiceUnavailable,
};

function fieldErrors(raw: unknown): ProblemField[] {
  if (!Array.isArray(raw)) return [];
  return raw.map((item: unknown) => {
    if (item && typeof item === "object") {
      const o = item as Record<string, unknown>;
      let field = o.field ?? o.loc ?? "";
      if (Array.isArray(field)) field = field.join(".");
      return { field: String(field), message: String(o.message ?? o.msg ?? "") };
    }
    return { field: "", message: String(item) };
  });
}

/** The `ApiError` subclass for an error answer (status >= 400) and its body text. */
export function errorFromResponse(
  init: { status: number; method: string; url: string; headers: Headers; text: string; attempts: number },
): ApiError {
  let problem: Problem | null = null;
  const ctype = init.headers.get("content-type") ?? "";
  if (ctype.includes("json") && init.text) {
    try {
      const parsed: unknown = JSON.parse(init.text);
      if (parsed && typeof parsed === "object" && !Array.isArray(parsed)) problem = parsed as Problem;
    } catch {
      problem = null;
    }
  }
  const cls = ERROR_CLASS_BY_STATUS[init.status] ?? (init.status >= 500 ? ServerError : ClientError);
  return new cls({ ...init, problem });
}
