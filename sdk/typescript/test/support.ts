// Shared by the tests: paths of the repository's files, vector loading, float comparisons.
import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import { gunzipSync } from "node:zlib";

/** sdk/typescript/build-test -> the repository root. */
export const REPO = join(dirname(fileURLToPath(import.meta.url)), "..", "..", "..");

export function readJson<T = any>(relativePath: string): T {
  const bytes = readFileSync(join(REPO, relativePath));
  return JSON.parse((relativePath.endsWith(".gz") ? gunzipSync(bytes) : bytes).toString("utf8")) as T;
}

/** Every entry of two (nested) number arrays within `tol` (absolute). */
export function assertClose(actual: unknown, expected: unknown, tol: number, what = "value"): void {
  const a = flat(actual);
  const e = flat(expected);
  assert.equal(a.length, e.length, `${what}: ${a.length} numbers, expected ${e.length}`);
  a.forEach((x, i) => {
    assert.ok(Math.abs(x - e[i]) <= tol, `${what}[${i}] = ${x}, expected ${e[i]} (tolerance ${tol})`);
  });
}

/** Angles (radians) equal modulo pi within `tol`. */
export function assertAngleModPi(actual: number, expected: number, tol: number, what = "angle"): void {
  let d = (actual - expected) % Math.PI;
  if (d > Math.PI / 2) d -= Math.PI;
  if (d < -Math.PI / 2) d += Math.PI;
  assert.ok(Math.abs(d) <= tol, `${what} = ${actual}, expected ${expected} modulo pi (tolerance ${tol})`);
}

function flat(v: unknown): number[] {
  if (typeof v === "number") return [v];
  if (Array.isArray(v) || ArrayBuffer.isView(v)) return Array.from(v as ArrayLike<unknown>).flatMap(flat);
  throw new TypeError(`not a number array: ${JSON.stringify(v)}`);
}
