/**
 * The retry policy: exponential backoff with jitter, honouring `Retry-After` (the same rules as
 * the Python SDK's `RetryPolicy`, docs/sdk.md "Errors and retries").
 *
 * - HTTP 429 and 503 are retried for every call (the server did not process the request); the
 *   wait is at least the server's `Retry-After` (seconds or an HTTP date). A `Retry-After` above
 *   `maxRetryAfterMs` is not waited for: the error is thrown at once (`retryAfterS` on it), so
 *   the app can reschedule instead of blocking.
 * - Network failures and timeouts are retried only for idempotent calls (GETs, localization,
 *   which computes without changing anything): `fetch` cannot tell whether a failed request
 *   reached the server, so creating, updating, deleting maps, starting sessions, sending
 *   tracking frames and starting builds are never replayed blindly. (Node's fetch does say
 *   "connection refused": that one is retried for every call.)
 * - Never: any other 4xx (the request is wrong) or other 5xx.
 *
 * Wait before retry k (k = 1, 2, ...): base = min(maxBackoffMs, initialBackoffMs *
 * multiplier^(k-1)), drawn uniformly in [base * (1 - jitter), base].
 */

/** Statuses that are retried. */
export const RETRY_STATUSES: ReadonlySet<number> = new Set([429, 503]);

export interface RetryOptions {
  /** Attempts in all, the first included (1 = never retry). Default 4. */
  maxAttempts?: number;
  /** Default 200 ms. */
  initialBackoffMs?: number;
  /** Default 2. */
  multiplier?: number;
  /** Default 5000 ms. */
  maxBackoffMs?: number;
  /** Fraction of the wait drawn at random, in [0, 1]. Default 0.5. */
  jitter?: number;
  /** Wait at least the server's Retry-After. Default true. */
  respectRetryAfter?: boolean;
  /** A Retry-After above this is not waited for (the error is thrown). Default 30000 ms. */
  maxRetryAfterMs?: number;
  /** Random source in [0, 1) of the jitter (seed it in tests). Default Math.random. */
  random?: () => number;
}

/** A validated retry policy (see the module documentation). */
export class RetryPolicy {
  readonly maxAttempts: number;
  readonly initialBackoffMs: number;
  readonly multiplier: number;
  readonly maxBackoffMs: number;
  readonly jitter: number;
  readonly respectRetryAfter: boolean;
  readonly maxRetryAfterMs: number;
  readonly random: () => number;

  constructor(options: RetryOptions = {}) {
    this.maxAttempts = options.maxAttempts ?? 4;
    this.initialBackoffMs = options.initialBackoffMs ?? 200;
    this.multiplier = options.multiplier ?? 2;
    this.maxBackoffMs = options.maxBackoffMs ?? 5000;
    this.jitter = options.jitter ?? 0.5;
    this.respectRetryAfter = options.respectRetryAfter ?? true;
    this.maxRetryAfterMs = options.maxRetryAfterMs ?? 30000;
    this.random = options.random ?? Math.random;
    if (!Number.isInteger(this.maxAttempts) || this.maxAttempts < 1) {
      throw new RangeError(`retry.maxAttempts: must be an integer >= 1, got ${this.maxAttempts}`);
    }
    for (const name of ["initialBackoffMs", "maxBackoffMs", "maxRetryAfterMs"] as const) {
      if (!(Number.isFinite(this[name]) && this[name] >= 0)) {
        throw new RangeError(`retry.${name}: must be finite and >= 0, got ${this[name]}`);
      }
    }
    if (!(Number.isFinite(this.multiplier) && this.multiplier >= 1)) {
      throw new RangeError(`retry.multiplier: must be >= 1, got ${this.multiplier}`);
    }
    if (!(this.jitter >= 0 && this.jitter <= 1)) {
      throw new RangeError(`retry.jitter: must be in [0, 1], got ${this.jitter}`);
    }
  }

  /** Jittered wait (ms) before retry `retryNumber` (1 for the first retry). */
  backoffMs(retryNumber: number): number {
    const base = Math.min(this.maxBackoffMs, this.initialBackoffMs * this.multiplier ** (retryNumber - 1));
    return base * (1 - this.jitter * this.random());
  }

  /** Wait (ms) before retrying after an answer with `status`, or null when it is not retried. */
  delayForResponseMs(status: number, retryAfter: string | null, retryNumber: number): number | null {
    if (!RETRY_STATUSES.has(status)) return null;
    let delay = this.backoffMs(retryNumber);
    if (this.respectRetryAfter) {
      const advisedS = parseRetryAfter(retryAfter);
      if (advisedS !== null) {
        if (advisedS * 1000 > this.maxRetryAfterMs) return null;
        delay = Math.max(delay, advisedS * 1000);
      }
    }
    return delay;
  }
}

/**
 * Seconds to wait from a `Retry-After` header: delta-seconds ("3", "1.5") or an HTTP date
 * (relative to `nowMs`, default now). null when absent or unparseable; never negative.
 */
export function parseRetryAfter(value: string | null | undefined, nowMs: number = Date.now()): number | null {
  if (value == null) return null;
  const v = value.trim();
  if (v === "") return null;
  let seconds: number;
  if (/^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$/.test(v)) {
    seconds = Number(v);
  } else {
    // HTTP dates name their zone (GMT); a date without one is not an HTTP date.
    if (!/\b(GMT|UTC|[+-]\d{4})\b/.test(v)) return null;
    const when = Date.parse(v);
    if (Number.isNaN(when)) return null;
    seconds = (when - nowMs) / 1000;
  }
  if (!Number.isFinite(seconds)) return null;
  return Math.max(0, seconds);
}

/** Resolves after `ms`, or rejects with the signal's reason when it aborts first. */
export function sleep(ms: number, signal?: AbortSignal): Promise<void> {
  return new Promise((resolve, reject) => {
    if (signal?.aborted) {
      reject(signal.reason);
      return;
    }
    const onAbort = () => {
      clearTimeout(timer);
      reject(signal?.reason);
    };
    const timer = setTimeout(() => {
      signal?.removeEventListener("abort", onAbort);
      resolve();
    }, ms);
    signal?.addEventListener("abort", onAbort, { once: true });
  });
}
