// WebXR and three.js conventions, with the real three.js (a dev dependency; the SDK itself
// only needs objects of its shape) and independent computations.
import assert from "node:assert/strict";
import { describe, it } from "node:test";
import { Group, Matrix4, Mesh, PerspectiveCamera, Quaternion, SphereGeometry, Vector3 } from "three";
import {
  applyWorldFromOdom,
  ellipsoidMatrix,
  invertPose,
  matrixFromXRRigidTransform,
  odomFromCameraFromXRView,
  poseMatrixFromQuaternionWxyz,
  setMatrix4,
  setObjectPose,
  threeCameraMatrix,
  transformPoint,
  worldFromCameraOpencvToOpengl,
  xrMatrixFromPose,
  xrOffsetForMap,
  xrRigidTransformInit,
  type Mat4,
} from "../dist/index.js";
import { assertClose, readJson } from "./support.js";

const poses = readJson("sdk/test-vectors/poses.json");
const T: Mat4 = poses.poses[3].world_from_camera;

describe("three.js", () => {
  it("setMatrix4 equals Matrix4.set with the row-major entries", () => {
    const m = setMatrix4(new Matrix4(), T);
    const expected = new Matrix4().set(...(T.flat() as Parameters<Matrix4["set"]>));
    assertClose(Array.from(m.elements), Array.from(expected.elements), 0, "elements");
    const p = new Vector3(0.3, -0.2, 1.1).applyMatrix4(m);
    assertClose([p.x, p.y, p.z], transformPoint(T, [0.3, -0.2, 1.1]), 1e-12, "point");
  });

  it("applyWorldFromOdom puts map points where odom_from_world sends them", () => {
    const worldFromOdom = poses.session_from_map.map_from_camera as Mat4;
    const scene = new Group();
    const mapGroup = applyWorldFromOdom(new Group(), worldFromOdom);
    scene.add(mapGroup);
    const object = new Mesh(new SphereGeometry(1));
    mapGroup.add(object);
    object.position.set(1.0, 2.0, 0.5); // a map point (metres)
    scene.updateMatrixWorld(true);
    const got = new Vector3().setFromMatrixPosition(object.matrixWorld);
    const expected = transformPoint(invertPose(worldFromOdom), [1.0, 2.0, 0.5]);
    assertClose([got.x, got.y, got.z], expected, 1e-12, "map point in the scene");
    assert.equal(mapGroup.matrixAutoUpdate, false);
  });

  it("ellipsoidMatrix maps the unit sphere onto the ellipsoid", () => {
    const obj = { center: [1.5, 1.1, 0.95], axes: [0.3, 0.05, 0.2], quaternion_wxyz: [0.9238795, 0, 0, 0.3826834] };
    const M = ellipsoidMatrix(obj);
    // the sphere's +X pole lands at centre + a * (first axis of R) = centre + 0.3 (cos 45, sin 45, 0)
    const c = Math.SQRT1_2;
    assertClose(transformPoint(M, [1, 0, 0]), [1.5 + 0.3 * c, 1.1 + 0.3 * c, 0.95], 1e-6, "+X pole");
    assertClose(transformPoint(M, [0, 0, 1]), [1.5, 1.1, 1.15], 1e-6, "+Z pole");
    const mesh = setObjectPose(new Mesh(new SphereGeometry(1)), M);
    mesh.updateMatrixWorld(true);
    assertClose(Array.from(mesh.matrixWorld.elements), Array.from(setMatrix4(new Matrix4(), M).elements), 0, "mesh");
  });

  it("a three.js camera looks where the OpenCV camera looks", () => {
    const cam = setObjectPose(new PerspectiveCamera(), threeCameraMatrix(T, "opencv"));
    cam.updateMatrixWorld(true);
    const forward = new Vector3();
    cam.getWorldDirection(forward); // three: the camera's -Z in the world
    const R = T.map((r) => r.slice(0, 3));
    assertClose([forward.x, forward.y, forward.z], [R[0][2], R[1][2], R[2][2]], 1e-12, "forward = OpenCV +Z");
  });
});

describe("WebXR", () => {
  it("XRRigidTransform.matrix (column-major float32) -> odom_from_camera", () => {
    const gl = worldFromCameraOpencvToOpengl(T);
    const view = { transform: { matrix: xrMatrixFromPose(gl) } };
    const got = odomFromCameraFromXRView(view).matrix as Mat4;
    assertClose(got, gl, 1e-6, "from the float32 matrix");
    // re-orthonormalised: a rotation to double precision
    const R = got.slice(0, 3).map((r) => r.slice(0, 3));
    const RRt = R.map((a) => R.map((b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2]));
    assertClose(RRt, [[1, 0, 0], [0, 1, 0], [0, 0, 1]], 1e-12, "R R^T");
  });

  it("position + orientation (scalar last) round trip", () => {
    const init = xrRigidTransformInit(T);
    const q = new Quaternion(init.orientation.x, init.orientation.y, init.orientation.z, init.orientation.w);
    const m = new Matrix4().compose(new Vector3(init.position.x, init.position.y, init.position.z), q, new Vector3(1, 1, 1));
    assertClose(Array.from(m.elements), Array.from(setMatrix4(new Matrix4(), T).elements), 1e-12, "three compose");
    assertClose(matrixFromXRRigidTransform(init), T, 1e-12, "back");
  });

  it("xrOffsetForMap is the map origin's pose in the reference space", () => {
    const worldFromOdom = poseMatrixFromQuaternionWxyz([Math.cos(0.3), 0, 0, Math.sin(0.3)], [2, -1, 0.5]);
    const off = matrixFromXRRigidTransform(xrOffsetForMap(worldFromOdom));
    assertClose(transformPoint(worldFromOdom, transformPoint(off, [0.4, 0.5, 0.6])), [0.4, 0.5, 0.6], 1e-12, "identity");
  });
});
