/**
 * WebXR conventions. WebXR poses (`XRViewerPose.transform`, `XRView.transform`,
 * `XRRigidTransform`) are `referenceSpace_from_object` rigid transforms with OpenGL camera
 * axes (+X right, +Y up, the view looking down -Z), metres; `XRRigidTransform.matrix` is a
 * Float32Array of 16 numbers COLUMN-major; `orientation` is a unit quaternion {x, y, z, w}
 * (scalar last). QuadLoc's poses are row-major with `quaternion_wxyz` scalar first.
 *
 * For a tracking session the XR reference space is the app's odometry frame: send each frame's
 * `odomFromCameraFromXRView(view)` with a session started with `convention: "opengl"`; the
 * answers' `world_from_odom` then anchors the map in the reference space
 * (`xrOffsetForMap(worldFromOdom)` or, in three.js, `three.ts`).
 *
 * Types are structural (no dependency on the WebXR type definitions): a real `XRView` or
 * `XRRigidTransform` fits.
 */
import {
  checkPose,
  columnMajorFromMatrix,
  invertPose,
  matrixFromColumnMajor,
  poseMatrixFromQuaternionWxyz,
  quaternionWxyzFromXyzw,
  quaternionWxyzTranslationFromPose,
  quaternionXyzwFromWxyz,
  type Mat4,
} from "./geometry.js";
import type { PoseInput } from "./models.js";

/** A DOMPointReadOnly-like point or quaternion. */
export interface XRPointLike {
  x: number;
  y: number;
  z: number;
  w: number;
}

/** What QuadLoc reads of an `XRRigidTransform`: its column-major `matrix`, or position + orientation. */
export interface XRRigidTransformLike {
  matrix?: ArrayLike<number>;
  position?: XRPointLike;
  orientation?: XRPointLike;
}

/** What QuadLoc reads of an `XRView` / `XRViewerPose`: its `transform`. */
export interface XRViewLike {
  transform: XRRigidTransformLike;
}

/** `new XRRigidTransform(position, orientation)` arguments. */
export interface XRRigidTransformInit {
  position: XRPointLike;
  orientation: XRPointLike;
}

/**
 * The row-major 4x4 `referenceSpace_from_object` of an XRRigidTransform (OpenGL camera axes
 * for a view), from its column-major `matrix` or, without one, its position and orientation.
 */
export function matrixFromXRRigidTransform(transform: XRRigidTransformLike): Mat4 {
  if (transform.matrix && transform.matrix.length === 16) {
    const T = matrixFromColumnMajor(transform.matrix);
    // Float32 matrices are orthonormal to ~1e-7 only: re-orthonormalise through the quaternion.
    const [q, t] = quaternionWxyzTranslationFromPose(snapRotation(T));
    return poseMatrixFromQuaternionWxyz(q, t);
  }
  const p = transform.position;
  const o = transform.orientation;
  if (!p || !o) throw new RangeError("transform: needs a 16-number matrix or position + orientation");
  const q = quaternionWxyzFromXyzw([o.x, o.y, o.z, o.w]);
  const n = Math.hypot(...q);
  return poseMatrixFromQuaternionWxyz(q.map((v) => v / n), [p.x / p.w, p.y / p.w, p.z / p.w]);
}

/** The nearest rotation of a 3x3 block that is orthonormal to float32 precision (Gram-Schmidt). */
function snapRotation(T: Mat4): Mat4 {
  const col = (c: number) => [T[0][c], T[1][c], T[2][c]];
  const dot = (a: number[], b: number[]) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const norm = (a: number[]) => a.map((v) => v / Math.hypot(...a));
  const x = norm(col(0));
  const y0 = col(1);
  const y = norm(y0.map((v, i) => v - dot(x, y0) * x[i]));
  const z = [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]];
  const out = T.map((row) => row.slice());
  for (let r = 0; r < 3; r++) {
    out[r][0] = x[r];
    out[r][1] = y[r];
    out[r][2] = z[r];
  }
  return out;
}

/**
 * `odom_from_camera` of a tracking frame from an `XRView` (or `XRViewerPose`): the view's pose
 * in the XR reference space, row-major, OpenGL camera axes: start the session with
 * `convention: "opengl"`. Returns the wire form `{matrix}`.
 */
export function odomFromCameraFromXRView(view: XRViewLike): PoseInput {
  return { matrix: matrixFromXRRigidTransform(view.transform) };
}

/** `new XRRigidTransform(...)` arguments of a row-major rigid pose (metres). */
export function xrRigidTransformInit(pose: Mat4): XRRigidTransformInit {
  const [q, t] = quaternionWxyzTranslationFromPose(pose);
  const [x, y, z, w] = quaternionXyzwFromWxyz(q);
  return { position: { x: t[0], y: t[1], z: t[2], w: 1 }, orientation: { x, y, z, w } };
}

/**
 * The origin offset that turns an XR reference space (the session's odometry frame) into the
 * map's frame: `refSpace.getOffsetReferenceSpace(new XRRigidTransform(o.position,
 * o.orientation))` with `o = xrOffsetForMap(worldFromOdom)`. The offset is the map origin's
 * pose in the reference space, `odom_from_world = inverse(world_from_odom)`; poses read in the
 * new space are map coordinates.
 */
export function xrOffsetForMap(worldFromOdom: Mat4): XRRigidTransformInit {
  return xrRigidTransformInit(invertPose(worldFromOdom));
}

/** The 16 column-major numbers of a pose, as `XRRigidTransform.matrix` holds them. */
export function xrMatrixFromPose(pose: Mat4): Float32Array {
  return Float32Array.from(columnMajorFromMatrix(checkPose("pose", pose)));
}
