/**
 * three.js helpers, structural (no dependency on three: any `Matrix4` / `Object3D` fits).
 * three.js is right-handed, +Y up in most scenes, and its cameras look down -Z with +Y up
 * (OpenGL camera axes); `Matrix4.elements` and `fromArray` are COLUMN-major.
 *
 * To draw a QuadLoc map in a scene whose frame is the app's odometry (a WebXR reference
 * space, an AR session), put the map's objects (map coordinates) in one group and give the
 * group the pose of the map in the scene: `applyWorldFromOdom(group, worldFromOdom)` sets
 * `group.matrix = odom_from_world = inverse(world_from_odom)` (a tracking answer's
 * `world_from_odom`, the same in both conventions).
 */
import {
  checkPose,
  columnMajorFromMatrix,
  convertCameraAxes,
  invertPose,
  matmul,
  poseMatrixFromQuaternionWxyz,
  type Convention,
  type Mat4,
} from "./geometry.js";

/** What is used of a three.js `Matrix4`. */
export interface Matrix4Like {
  fromArray(array: ArrayLike<number>, offset?: number): unknown;
}

/** What is used of a three.js `Object3D` (a `Group`, a `Mesh`, a `Camera`). */
export interface Object3DLike {
  matrix: Matrix4Like;
  matrixAutoUpdate: boolean;
  matrixWorldNeedsUpdate: boolean;
}

/** Sets a three.js `Matrix4` to a row-major 4x4 (e.g. an answer's `matrix`); returns it. */
export function setMatrix4<M extends Matrix4Like>(target: M, rowMajor: Mat4): M {
  target.fromArray(columnMajorFromMatrix(rowMajor));
  return target;
}

/**
 * Places `object` with a fixed row-major `pose` (its matrix is set, `matrixAutoUpdate`
 * turned off so that three.js does not overwrite it from position / quaternion / scale).
 */
export function setObjectPose<O extends Object3DLike>(object: O, pose: Mat4): O {
  setMatrix4(object.matrix, pose);
  object.matrixAutoUpdate = false;
  object.matrixWorldNeedsUpdate = true;
  return object;
}

/**
 * Anchors a group holding the map (children in map coordinates) in a scene whose frame is the
 * app's odometry frame: the group's matrix becomes `odom_from_world = inverse(worldFromOdom)`.
 */
export function applyWorldFromOdom<O extends Object3DLike>(mapGroup: O, worldFromOdom: Mat4): O {
  return setObjectPose(mapGroup, invertPose(worldFromOdom));
}

/**
 * The matrix to give a three.js camera for a QuadLoc `worldFromCamera` with camera axes
 * `convention` (three.js cameras use OpenGL axes: an OpenCV pose is flipped first). Row-major;
 * pass it to `setObjectPose(camera, ...)`.
 */
export function threeCameraMatrix(worldFromCamera: Mat4, convention: Convention = "opencv"): Mat4 {
  return convertCameraAxes(worldFromCamera, convention, "opengl");
}

/** A map object of a QuadLoc map document (docs/maps.md): centre, semi-axes, orientation. */
export interface MapObjectLike {
  center: number[];
  axes: number[];
  quaternion_wxyz?: number[];
  rotation?: number[][];
}

/**
 * The row-major 4x4 that maps the unit sphere onto a map object's ellipsoid:
 * `[[R diag(axes), center], [0, 1]]` (R = the ellipsoid's axes in the map, metres). A
 * `SphereGeometry(1)` mesh with `setObjectPose(mesh, ellipsoidMatrix(obj))` draws it.
 */
export function ellipsoidMatrix(obj: MapObjectLike): Mat4 {
  const pose = obj.rotation
    ? checkPose("object.rotation", [...obj.rotation.map((r, i) => [...r, obj.center[i]]), [0, 0, 0, 1]])
    : poseMatrixFromQuaternionWxyz(obj.quaternion_wxyz ?? [1, 0, 0, 0], obj.center);
  const [a, b, c] = obj.axes;
  return matmul(pose, [
    [a, 0, 0, 0],
    [0, b, 0, 0],
    [0, 0, c, 0],
    [0, 0, 0, 1],
  ]);
}
