// The shared test vectors (sdk/test-vectors/*.json, computed by the Python SDK) through the
// TypeScript SDK's helpers: the three SDKs give the same numbers.
import assert from "node:assert/strict";
import { describe, it } from "node:test";
import {
  canonicalEllipse,
  columnMajorFromMatrix,
  covarianceOpencvToOpengl,
  ellipseFromBox,
  ellipseFromMask,
  GeometryError,
  invertPose,
  logVarianceFromSigma,
  matrixFromColumnMajor,
  matrixFromQuaternionWxyz,
  quaternionWxyzFromMatrix,
  quaternionWxyzFromXyzw,
  quaternionWxyzTranslationFromPose,
  quaternionXyzwFromWxyz,
  poseMatrixFromQuaternionWxyz,
  sessionFromMap,
  sigmaFromLogVariance,
  toCameraFromWorld,
  unityPoseFromWorldFromCamera,
  worldFromCameraOpencvToOpengl,
  worldFromCameraOpenglToOpencv,
  type Convention,
  type CanonicalEllipse,
} from "../dist/index.js";
import { assertAngleModPi, assertClose, readJson } from "./support.js";

const poses = readJson("sdk/test-vectors/poses.json");
const ellipses = readJson("sdk/test-vectors/ellipses.json");
const TOL: number = poses.tolerance.absolute; // 1e-9, stated in the file

function assertEllipse(actual: CanonicalEllipse, expected: CanonicalEllipse, what: string): void {
  assertClose([actual.cx, actual.cy, actual.a, actual.b], [expected.cx, expected.cy, expected.a, expected.b], TOL, what);
  assert.ok(actual.angle >= -Math.PI / 2 && actual.angle < Math.PI / 2, `${what}: angle ${actual.angle} not canonical`);
  assertAngleModPi(actual.angle, expected.angle, TOL, `${what}.angle`);
}

describe("pose vectors", () => {
  it("quaternion <-> rotation matrix, both orders", () => {
    assert.ok(poses.quaternions.length >= 10);
    for (const c of poses.quaternions) {
      assertClose(quaternionWxyzFromMatrix(c.matrix), c.quaternion_wxyz, TOL, "quaternion_wxyz");
      assertClose(quaternionXyzwFromWxyz(c.quaternion_wxyz), c.quaternion_xyzw, 0, "xyzw");
      assertClose(quaternionWxyzFromXyzw(c.quaternion_xyzw), c.quaternion_wxyz, 0, "wxyz");
      assertClose(matrixFromQuaternionWxyz(c.quaternion_wxyz), c.matrix_from_quaternion, TOL, "R(q)");
    }
  });

  it("inversion, axes, layouts and Unity", () => {
    for (const c of poses.poses) {
      const T = c.world_from_camera;
      assertClose(toCameraFromWorld(T), c.camera_from_world, TOL, `${c.name} camera_from_world`);
      assertClose(invertPose(c.camera_from_world), T, TOL, `${c.name} inverse`);
      const [q, t] = quaternionWxyzTranslationFromPose(T);
      assertClose(q, c.quaternion_wxyz, TOL, `${c.name} q`);
      assertClose(t, c.translation_m, 0, `${c.name} t`);
      assertClose(poseMatrixFromQuaternionWxyz(c.quaternion_wxyz, c.translation_m), T, TOL, `${c.name} from q`);
      assertClose(columnMajorFromMatrix(T), c.column_major, 0, `${c.name} column-major`);
      assertClose(matrixFromColumnMajor(c.column_major), T, 0, `${c.name} from column-major`);
      assertClose(worldFromCameraOpencvToOpengl(T), c.world_from_camera_opengl, TOL, `${c.name} opengl`);
      assertClose(worldFromCameraOpenglToOpencv(c.world_from_camera_opengl), T, TOL, `${c.name} opencv`);
      assert.equal(c.unity.length, 4);
      for (const u of c.unity) {
        const got = unityPoseFromWorldFromCamera(u.world_from_camera, u.convention as Convention, u.world_up);
        assertClose(got.position, u.position, TOL, `${c.name} unity ${u.convention}/${u.world_up} position`);
        assertClose(got.rotationXyzw, u.rotation_xyzw, TOL, `${c.name} unity ${u.convention}/${u.world_up} rotation`);
      }
    }
  });

  it("covariance flip and session_from_map", () => {
    assertClose(covarianceOpencvToOpengl(poses.covariance.opencv), poses.covariance.opengl, TOL, "covariance");
    const s = poses.session_from_map;
    assertClose(sessionFromMap(s.session_from_camera, s.map_from_camera), s.session_from_map, TOL, "session_from_map");
  });

  it("refuses what is not a rigid pose, naming the argument", () => {
    for (const bad of poses.invalid_poses) {
      assert.throws(() => invertPose(bad.matrix), (e: unknown) => e instanceof GeometryError && e.field === "pose", bad.why);
      assert.throws(() => unityPoseFromWorldFromCamera(bad.matrix), GeometryError, bad.why);
    }
  });
});

describe("ellipse vectors", () => {
  it("box -> inscribed ellipse", () => {
    for (const c of ellipses.boxes) {
      assertEllipse(ellipseFromBox(c.box), c.ellipse, `box ${c.box}`);
      const [xmin, ymin, xmax, ymax] = c.box;
      assertEllipse(ellipseFromBox({ xmin, ymin, xmax, ymax }), c.ellipse, `box object ${c.box}`);
    }
    assert.throws(() => ellipseFromBox([10, 10, 5, 20]), (e: unknown) => e instanceof GeometryError && e.field === "box.xmax");
  });

  it("canonical ellipses", () => {
    for (const c of ellipses.canonical) {
      const [cx, cy, a, b, angle] = c.input;
      assertEllipse(canonicalEllipse(cx, cy, a, b, angle), c.ellipse, `canonical ${c.input}`);
    }
  });

  it("mask -> moment-matched ellipse", () => {
    assert.ok(ellipses.masks.length >= 4);
    for (const m of ellipses.masks) {
      const data = new Uint8Array(m.width * m.height);
      for (const [row, c0, c1] of m.runs) data.fill(1, row * m.width + c0, row * m.width + c1);
      assertEllipse(ellipseFromMask({ width: m.width, height: m.height, data }), m.ellipse, `mask ${m.name}`);
    }
    assert.throws(() => ellipseFromMask({ width: 2, height: 2, data: [0, 0, 0, 0] }), /no non-zero pixel/);
    assert.throws(() => ellipseFromMask({ width: 3, height: 2, data: [1, 1] }), (e: unknown) => e instanceof GeometryError && e.field === "mask.data");
  });

  it("log-variance <-> sigma", () => {
    for (const c of ellipses.log_variance) {
      assertClose(sigmaFromLogVariance(c.log_variance), c.sigma, TOL, "sigma");
      assertClose(logVarianceFromSigma(c.sigma), c.log_variance, TOL, "log_variance");
    }
    assert.throws(() => logVarianceFromSigma(0), GeometryError);
  });
});
