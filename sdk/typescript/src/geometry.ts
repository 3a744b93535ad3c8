/**
 * Geometry helpers an app needs before and after calling QuadLoc: box / mask -> ellipse,
 * log-variance -> sigma, pose directions, camera-axis conventions, quaternion orders, matrix
 * layouts and Unity's left-handed axes. Pure TypeScript (no dependency); a port of the Python
 * SDK's `quadloc_sdk.geometry`, checked against the same test vectors
 * (`sdk/test-vectors/*.json`, computed by the Python SDK).
 *
 * Conventions (the server's):
 * - Pixels: origin at the top-left corner of the top-left pixel, +x right, +y down; the centre
 *   of pixel (row i, column j) is (j + 0.5, i + 0.5).
 * - Ellipses `{cx, cy, a, b, angle}`: centre px, SEMI-axes px (`a` along `angle`), `angle` in
 *   RADIANS from +x towards +y. Returned ellipses are canonical: a >= b, angle in [-pi/2, pi/2).
 * - Poses are 4x4 rigid transforms named by direction, ROW-major (`Mat4`: a list of 4 rows,
 *   `T[r][c]`, as the wire's `matrix`): `worldFromCamera` maps camera coordinates to world
 *   coordinates; `cameraFromWorld` is its inverse (OpenCV's [R | t]). Metres.
 * - Camera axes: "opencv" = +X right, +Y down, +Z forward (QuadLoc's default); "opengl" =
 *   WebXR / ARKit / ARCore / three.js: +X right, +Y up, -Z forward. They differ by
 *   F = diag(1, -1, -1) on the camera side: worldFromCamera_gl = worldFromCamera_cv * diag(1, -1, -1, 1).
 * - Quaternions `QuaternionWxyz` are scalar first, unit norm, w >= 0.
 * - Covariances of poses are 6x6 in the order [omega_x, omega_y, omega_z, v_x, v_y, v_z]
 *   (radians, metres), right perturbation, camera (body) frame.
 */

import type { Box, Ellipse } from "./models.js";

/** An ellipse as the helpers return it: every field present, canonical (a >= b, angle in [-pi/2, pi/2)). */
export type CanonicalEllipse = Required<Ellipse>;

/** 3 numbers (metres unless stated). */
export type Vec3 = [number, number, number];
/** Unit quaternion, scalar first: [w, x, y, z]. */
export type QuaternionWxyz = [number, number, number, number];
/** Unit quaternion, scalar last: [x, y, z, w] (WebXR, three.js, Unity, ARKit/simd, ARCore). */
export type QuaternionXyzw = [number, number, number, number];
/** 3x3 matrix as a list of 3 rows. */
export type Mat3 = number[][];
/** 4x4 matrix as a list of 4 ROWS (row-major, `T[r][c]`), like the wire's `matrix`. */
export type Mat4 = number[][];
/** Camera axes of a pose. */
export type Convention = "opencv" | "opengl";

/** Tolerance on max|R R^T - I| and |det R - 1| for the rotation block of a pose. */
export const ORTHONORMAL_TOLERANCE = 1e-6;
/** Tolerance on ||q| - 1| for a unit quaternion. */
export const QUATERNION_NORM_TOLERANCE = 1e-6;

/** Bad input to a helper; `field` names the argument. */
export class GeometryError extends RangeError {
  readonly field: string;
  constructor(field: string, message: string) {
    super(`${field}: ${message}`);
    this.name = "GeometryError";
    this.field = field;
  }
}

// ------------------------------------------------------------------------------- ellipses

/** The same ellipse with a >= b and angle (radians) in [-pi/2, pi/2). */
export function canonicalEllipse(cx: number, cy: number, a: number, b: number, angle: number): CanonicalEllipse {
  if (b > a) {
    [a, b] = [b, a];
    angle += Math.PI / 2;
  }
  angle = pyMod(angle + Math.PI / 2, Math.PI) - Math.PI / 2;
  return { cx, cy, a, b, angle };
}

/** Python's `%` (the result has the sign of the divisor). */
function pyMod(x: number, m: number): number {
  const r = x % m;
  return r !== 0 && r < 0 !== m < 0 ? r + m : r;
}

function finite(field: string, values: ArrayLike<number>): void {
  for (let i = 0; i < values.length; i++) {
    if (typeof values[i] !== "number" || !Number.isFinite(values[i])) {
      throw new GeometryError(field, `must be finite numbers, got ${String(values[i])} at ${i}`);
    }
  }
}

/**
 * The axis-aligned ellipse INSCRIBED in a detection box (what the server does with `box`):
 * centre = box centre, semi-axes = half the width / height, angle 0, then made canonical (a tall
 * box gives a = half its height and angle = -pi/2). `box`: `{xmin, ymin, xmax, ymax}` or
 * `[xmin, ymin, xmax, ymax]`, px.
 */
export function ellipseFromBox(box: Box | readonly [number, number, number, number]): CanonicalEllipse {
  if (Array.isArray(box) && box.length !== 4) {
    throw new GeometryError("box", `expected [xmin, ymin, xmax, ymax], got ${box.length} values`);
  }
  const b = Array.isArray(box)
    ? { xmin: box[0], ymin: box[1], xmax: box[2], ymax: box[3] }
    : (box as Box);
  finite("box", [b.xmin, b.ymin, b.xmax, b.ymax]);
  if (!(b.xmax > b.xmin)) throw new GeometryError("box.xmax", `must be > xmin (${b.xmin}), got ${b.xmax}`);
  if (!(b.ymax > b.ymin)) throw new GeometryError("box.ymax", `must be > ymin (${b.ymin}), got ${b.ymax}`);
  return canonicalEllipse(
    (b.xmin + b.xmax) / 2,
    (b.ymin + b.ymax) / 2,
    (b.xmax - b.xmin) / 2,
    (b.ymax - b.ymin) / 2,
    0,
  );
}

/**
 * A binary instance mask, row-major: pixel (row i, column j) is `data[i * width + j]`;
 * non-zero = object (a segmentation model's output, an alpha channel copied out, ...).
 */
export interface Mask {
  width: number;
  height: number;
  data: ArrayLike<number>;
}

/**
 * Moment-matched ellipse of a binary mask: the ellipse with the same area centroid and second
 * moments as the pixel region, each pixel a unit square centred at (j + 0.5, i + 0.5) (so the
 * region's covariance is the pixel centres' covariance plus 1/12 on the diagonal). Uses every
 * pixel (all connected components); robust to ragged or partial masks. A uniform filled ellipse
 * with semi-axes (a, b) has covariance R diag(a^2, b^2) R^T / 4, so a, b = 2 sqrt(eigenvalues).
 * Same result as the Python SDK's `ellipse_from_mask(mask)` (method "moments").
 */
export function ellipseFromMask(mask: Mask): CanonicalEllipse {
  const { width, height, data } = mask;
  if (!Number.isInteger(width) || !Number.isInteger(height) || width < 1 || height < 1) {
    throw new GeometryError("mask", `width and height must be positive integers, got ${width} x ${height}`);
  }
  if (data.length !== width * height) {
    throw new GeometryError("mask.data", `expected width * height = ${width * height} values, got ${data.length}`);
  }
  let n = 0;
  let sx = 0;
  let sy = 0;
  for (let i = 0; i < height; i++) {
    for (let j = 0; j < width; j++) {
      if (data[i * width + j] !== 0) {
        n++;
        sx += j + 0.5;
        sy += i + 0.5;
      }
    }
  }
  if (n === 0) throw new GeometryError("mask", "no non-zero pixel");
  const mx = sx / n;
  const my = sy / n;
  let sxx = 0;
  let syy = 0;
  let sxy = 0;
  for (let i = 0; i < height; i++) {
    for (let j = 0; j < width; j++) {
      if (data[i * width + j] !== 0) {
        const dx = j + 0.5 - mx;
        const dy = i + 0.5 - my;
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
      }
    }
  }
  return ellipseFromSecondMoments("mask", mx, my, sxx / n + 1 / 12, syy / n + 1 / 12, sxy / n);
}

/** Moment-matched ellipse of a 2x2 covariance [[sxx, sxy], [sxy, syy]] (px^2) at (mx, my). */
function ellipseFromSecondMoments(
  field: string, mx: number, my: number, sxx: number, syy: number, sxy: number,
): CanonicalEllipse {
  const half = (sxx - syy) / 2;
  const r = Math.hypot(half, sxy);
  const mean = (sxx + syy) / 2;
  const major = mean + r;
  const minor = mean - r;
  if (!(minor > 0)) throw new GeometryError(field, "the region is degenerate (zero width in some direction)");
  // Direction of the major eigenvector: half the angle of (sxx - syy, 2 sxy).
  const angle = 0.5 * Math.atan2(2 * sxy, sxx - syy);
  return canonicalEllipse(mx, my, 2 * Math.sqrt(major), 2 * Math.sqrt(minor), angle);
}

/** Detector log-variance alpha = log sigma^2 -> sigma = exp(alpha / 2). */
export function sigmaFromLogVariance(logVariance: number): number {
  finite("logVariance", [logVariance]);
  return Math.exp(logVariance / 2);
}

/** Inverse of `sigmaFromLogVariance`: alpha = 2 log sigma (sigma > 0). */
export function logVarianceFromSigma(sigma: number): number {
  finite("sigma", [sigma]);
  if (!(sigma > 0)) throw new GeometryError("sigma", `must be > 0, got ${sigma}`);
  return 2 * Math.log(sigma);
}

// ------------------------------------------------------------------------------- matrices

/** A deep copy of a 4x4 row-major matrix, checked to be 4 rows of 4 finite numbers. */
function mat4(field: string, m: Mat4): Mat4 {
  if (!Array.isArray(m) || m.length !== 4 || m.some((row) => !Array.isArray(row) && !ArrayBuffer.isView(row))) {
    throw new GeometryError(field, "expected 4 rows of 4 numbers (row-major)");
  }
  const out = m.map((row) => Array.from(row as ArrayLike<number>));
  if (out.some((row) => row.length !== 4)) throw new GeometryError(field, "expected 4 rows of 4 numbers (row-major)");
  out.forEach((row) => finite(field, row));
  return out;
}

/** Product of two 4x4 (or 3x3) row-major matrices. */
export function matmul(a: number[][], b: number[][]): number[][] {
  const n = a.length;
  const out: number[][] = [];
  for (let r = 0; r < n; r++) {
    const row: number[] = [];
    for (let c = 0; c < b[0].length; c++) {
      let s = 0;
      for (let k = 0; k < b.length; k++) s += a[r][k] * b[k][c];
      row.push(s);
    }
    out.push(row);
  }
  return out;
}

/** `T` applied to the point `p` (metres): the first three entries of T [p, 1]. */
export function transformPoint(T: Mat4, p: readonly number[]): Vec3 {
  return [0, 1, 2].map((r) => T[r][0] * p[0] + T[r][1] * p[1] + T[r][2] * p[2] + T[r][3]) as Vec3;
}

/** Identity 4x4. */
export function identity4(): Mat4 {
  return [0, 1, 2, 3].map((r) => [0, 1, 2, 3].map((c) => (r === c ? 1 : 0)));
}

/** Validates a rigid 4x4 pose (last row [0,0,0,1], proper rotation); returns a copy. */
export function checkPose(field: string, pose: Mat4): Mat4 {
  const T = mat4(field, pose);
  const last = [0, 0, 0, 1];
  if (T[3].some((v, i) => Math.abs(v - last[i]) > 1e-9)) {
    throw new GeometryError(field, "last row must be [0, 0, 0, 1]");
  }
  checkRotation(field, T.slice(0, 3).map((row) => row.slice(0, 3)));
  return T;
}

function checkRotation(field: string, R: Mat3): void {
  let err = 0;
  for (let i = 0; i < 3; i++) {
    for (let j = 0; j < 3; j++) {
      let s = 0;
      for (let k = 0; k < 3; k++) s += R[i][k] * R[j][k];
      err = Math.max(err, Math.abs(s - (i === j ? 1 : 0)));
    }
  }
  const det =
    R[0][0] * (R[1][1] * R[2][2] - R[1][2] * R[2][1]) -
    R[0][1] * (R[1][0] * R[2][2] - R[1][2] * R[2][0]) +
    R[0][2] * (R[1][0] * R[2][1] - R[1][1] * R[2][0]);
  if (err > ORTHONORMAL_TOLERANCE || Math.abs(det - 1) > ORTHONORMAL_TOLERANCE) {
    throw new GeometryError(field, `rotation block is not a proper rotation (max|R R^T - I| = ${err.toPrecision(3)})`);
  }
}

/** `bFromA` from a rigid `aFromB`, using R^T (no general inverse). */
export function invertPose(aFromB: Mat4): Mat4 {
  const T = checkPose("pose", aFromB);
  const out = identity4();
  for (let r = 0; r < 3; r++) {
    for (let c = 0; c < 3; c++) out[r][c] = T[c][r];
  }
  for (let r = 0; r < 3; r++) {
    out[r][3] = -(out[r][0] * T[0][3] + out[r][1] * T[1][3] + out[r][2] * T[2][3]);
  }
  return out;
}

/** `worldFromCamera` (the camera's pose in the map) from `cameraFromWorld` (OpenCV [R | t]). */
export function toWorldFromCamera(cameraFromWorld: Mat4): Mat4 {
  return invertPose(cameraFromWorld);
}

/** `cameraFromWorld` (OpenCV [R | t]) from `worldFromCamera`. */
export function toCameraFromWorld(worldFromCamera: Mat4): Mat4 {
  return invertPose(worldFromCamera);
}

const FLIP4: Mat4 = [
  [1, 0, 0, 0],
  [0, -1, 0, 0],
  [0, 0, -1, 0],
  [0, 0, 0, 1],
];

/**
 * Camera pose with OpenCV camera axes -> the same pose with OpenGL / WebXR / ARKit axes:
 * worldFromCamera_gl = worldFromCamera_cv * diag(1, -1, -1, 1). The camera centre is unchanged;
 * the world frame is untouched.
 */
export function worldFromCameraOpencvToOpengl(worldFromCameraOpencv: Mat4): Mat4 {
  return matmul(checkPose("worldFromCamera", worldFromCameraOpencv), FLIP4);
}

/** Inverse of `worldFromCameraOpencvToOpengl` (the flip is its own inverse). */
export function worldFromCameraOpenglToOpencv(worldFromCameraOpengl: Mat4): Mat4 {
  return matmul(checkPose("worldFromCamera", worldFromCameraOpengl), FLIP4);
}

/** A pose's camera axes changed from `from` to `to` (a no-op when they are equal). */
export function convertCameraAxes(worldFromCamera: Mat4, from: Convention, to: Convention): Mat4 {
  for (const [name, v] of [["from", from], ["to", to]] as const) {
    if (v !== "opencv" && v !== "opengl") throw new GeometryError(name, `must be "opencv" or "opengl", got ${String(v)}`);
  }
  const T = checkPose("worldFromCamera", worldFromCamera);
  return from === to ? T : matmul(T, FLIP4);
}

/**
 * A 6x6 body-frame pose covariance [omega, v] re-expressed in the flipped camera axes:
 * cov_gl = J cov_cv J^T with J = diag(1, -1, -1, 1, -1, -1). Its own inverse.
 */
export function covarianceOpencvToOpengl(covariance: number[][]): number[][] {
  if (!Array.isArray(covariance) || covariance.length !== 6 || covariance.some((r) => r.length !== 6)) {
    throw new GeometryError("covariance", "expected a 6x6 matrix (6 rows of 6 numbers)");
  }
  const j = [1, -1, -1, 1, -1, -1];
  return covariance.map((row, r) => row.map((v, c) => v * j[r] * j[c]));
}

/**
 * Anchors the map in an AR session: sessionFromCamera * inverse(mapFromCamera), both poses of
 * the SAME frame with the SAME camera axes (ask the server for `output_convention: "opengl"` to
 * use WebXR / ARKit poses as they are). Map points go to the session with
 * `transformPoint(sessionFromMap, X)`.
 */
export function sessionFromMap(sessionFromCamera: Mat4, mapFromCamera: Mat4): Mat4 {
  return matmul(checkPose("sessionFromCamera", sessionFromCamera), invertPose(mapFromCamera));
}

// ------------------------------------------------------------------------------- quaternions

/** 3x3 rotation from a unit quaternion [w, x, y, z] (norm within 1e-6 of 1, renormalised). */
export function matrixFromQuaternionWxyz(quaternionWxyz: readonly number[]): Mat3 {
  if (quaternionWxyz.length !== 4) throw new GeometryError("quaternionWxyz", `expected 4 numbers, got ${quaternionWxyz.length}`);
  finite("quaternionWxyz", quaternionWxyz);
  const n = Math.hypot(...quaternionWxyz);
  if (Math.abs(n - 1) > QUATERNION_NORM_TOLERANCE) {
    throw new GeometryError("quaternionWxyz", `must have unit norm, got |q| = ${n}`);
  }
  const [w, x, y, z] = quaternionWxyz.map((v) => v / n);
  return [
    [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
    [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
    [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
  ];
}

/**
 * Unit quaternion [w, x, y, z], w >= 0, of a 3x3 rotation (Shepperd's method: the largest of
 * 4w^2, 4x^2, 4y^2, 4z^2 is taken from the diagonal, so no division by a small number happens).
 */
export function quaternionWxyzFromMatrix(rotation: Mat3): QuaternionWxyz {
  if (!Array.isArray(rotation) || rotation.length !== 3 || rotation.some((r) => r.length !== 3)) {
    throw new GeometryError("rotation", "expected a 3x3 matrix (3 rows of 3 numbers)");
  }
  const r = rotation.map((row) => Array.from(row));
  r.forEach((row) => finite("rotation", row));
  checkRotation("rotation", r);
  const [d0, d1, d2] = [r[0][0], r[1][1], r[2][2]];
  const cand: number[][] = [
    [1 + d0 + d1 + d2, r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]],
    [r[2][1] - r[1][2], 1 + d0 - d1 - d2, r[0][1] + r[1][0], r[0][2] + r[2][0]],
    [r[0][2] - r[2][0], r[0][1] + r[1][0], 1 - d0 + d1 - d2, r[1][2] + r[2][1]],
    [r[1][0] - r[0][1], r[0][2] + r[2][0], r[1][2] + r[2][1], 1 - d0 - d1 + d2],
  ];
  const pivots = [1 + d0 + d1 + d2, 1 + d0 - d1 - d2, 1 - d0 + d1 - d2, 1 - d0 - d1 + d2];
  let p = 0;
  for (let i = 1; i < 4; i++) if (pivots[i] > pivots[p]) p = i;
  const q = cand[p];
  const n = Math.hypot(...q);
  const s = q[0] < 0 ? -1 / n : 1 / n;
  return q.map((v) => v * s) as QuaternionWxyz;
}

/** [x, y, z, w] (scalar last: WebXR, three.js, Unity, ARKit/simd, ARCore) from [w, x, y, z]. */
export function quaternionXyzwFromWxyz(q: readonly number[]): QuaternionXyzw {
  if (q.length !== 4) throw new GeometryError("quaternionWxyz", `expected 4 numbers, got ${q.length}`);
  return [q[1], q[2], q[3], q[0]];
}

/** [w, x, y, z] from [x, y, z, w]; inverse of `quaternionXyzwFromWxyz`. */
export function quaternionWxyzFromXyzw(q: readonly number[]): QuaternionWxyz {
  if (q.length !== 4) throw new GeometryError("quaternionXyzw", `expected 4 numbers, got ${q.length}`);
  return [q[3], q[0], q[1], q[2]];
}

/** 4x4 pose [[R(q), t], [0, 1]] from `quaternionWxyz` and `translation` (metres). */
export function poseMatrixFromQuaternionWxyz(quaternionWxyz: readonly number[], translation: readonly number[]): Mat4 {
  const R = matrixFromQuaternionWxyz(quaternionWxyz);
  if (translation.length !== 3) throw new GeometryError("translation", `expected 3 numbers, got ${translation.length}`);
  finite("translation", translation);
  return [
    [...R[0], translation[0]],
    [...R[1], translation[1]],
    [...R[2], translation[2]],
    [0, 0, 0, 1],
  ];
}

/** [quaternionWxyz, translation] of a 4x4 pose; inverse of `poseMatrixFromQuaternionWxyz`. */
export function quaternionWxyzTranslationFromPose(pose: Mat4): [QuaternionWxyz, Vec3] {
  const T = checkPose("pose", pose);
  return [quaternionWxyzFromMatrix(T.slice(0, 3).map((row) => row.slice(0, 3))), [T[0][3], T[1][3], T[2][3]]];
}

// ------------------------------------------------------------------------------- layouts

/**
 * The 16 entries of a 4x4 matrix column after column: what WebXR (`XRRigidTransform.matrix`),
 * three.js (`Matrix4.fromArray`, `.elements`), WebGL / glMatrix, Unity's `Matrix4x4` and simd
 * take. QuadLoc's `matrix` is row-major (answers also carry `matrix_column_major`).
 */
export function columnMajorFromMatrix(matrix: Mat4): number[] {
  const M = mat4("matrix", matrix);
  const out: number[] = [];
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) out.push(M[r][c]);
  return out;
}

/** Row-major 4x4 from 16 numbers column after column (inverse of `columnMajorFromMatrix`). */
export function matrixFromColumnMajor(values: ArrayLike<number>): Mat4 {
  if (values.length !== 16) throw new GeometryError("values", `expected 16 numbers, got ${values.length}`);
  finite("values", values);
  return [0, 1, 2, 3].map((r) => [0, 1, 2, 3].map((c) => Number(values[c * 4 + r])));
}

/** The 4x4 row-major matrix of a wire pose (an answer's `world_from_camera`, `world_from_odom`). */
export function poseMatrix(pose: { matrix: number[][] }): Mat4 {
  return checkPose("pose.matrix", pose.matrix);
}

// ------------------------------------------------------------------------------- Unity

/** Unity camera axes (+X right, +Y up, +Z forward, left-handed) from OpenCV camera axes. */
export const UNITY_CAMERA_FROM_OPENCV: Mat3 = [
  [1, 0, 0],
  [0, -1, 0],
  [0, 0, 1],
];
const UNITY_WORLD_FROM_MAP: Record<"y" | "z", Mat3> = {
  // right-handed Y-up world (WebXR / ARKit / ARCore session, glTF): mirror Z (as AR Foundation)
  y: [
    [1, 0, 0],
    [0, 1, 0],
    [0, 0, -1],
  ],
  // right-handed Z-up world (the demo Chess map, ROS, Blender): swap Y and Z
  z: [
    [1, 0, 0],
    [0, 0, 1],
    [0, 1, 0],
  ],
};

/**
 * A QuadLoc `worldFromCamera` as a Unity Transform of a camera under the map's root:
 * `{position, rotationXyzw}` (metres; `new Quaternion(x, y, z, w)`). Unity is left-handed, so
 * two reflections do it: R_unity = M_w R_cv M_c, position = M_w t, with M_c = diag(1, -1, 1)
 * and M_w mirroring Z (`worldUp: "y"`) or swapping Y and Z (`worldUp: "z"`, the default, for a
 * Z-up map such as the demo). `convention`: the camera axes of the given pose. The Python SDK's
 * `unity_pose_from_world_from_camera` (the reference) and the C# SDK give the same numbers.
 */
export function unityPoseFromWorldFromCamera(
  worldFromCamera: Mat4,
  convention: Convention = "opencv",
  worldUp: "y" | "z" = "z",
): { position: Vec3; rotationXyzw: QuaternionXyzw } {
  if (worldUp !== "y" && worldUp !== "z") throw new GeometryError("worldUp", `must be "y" or "z", got ${String(worldUp)}`);
  if (convention !== "opencv" && convention !== "opengl") {
    throw new GeometryError("convention", `must be "opencv" or "opengl", got ${String(convention)}`);
  }
  let T = checkPose("worldFromCamera", worldFromCamera);
  if (convention === "opengl") T = matmul(T, FLIP4);
  const Mw = UNITY_WORLD_FROM_MAP[worldUp];
  const R = T.slice(0, 3).map((row) => row.slice(0, 3));
  const Ru = matmul(matmul(Mw, R), UNITY_CAMERA_FROM_OPENCV);
  const t = [T[0][3], T[1][3], T[2][3]];
  const position = [0, 1, 2].map((r) => Mw[r][0] * t[0] + Mw[r][1] * t[1] + Mw[r][2] * t[2]) as Vec3;
  return { position, rotationXyzw: quaternionXyzwFromWxyz(quaternionWxyzFromMatrix(Ru)) };
}
