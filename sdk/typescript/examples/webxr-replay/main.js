// A WebXR-style app without a headset: the frames of a recording (docs/examples/track_chess.json)
// stand in for XRFrames. Each frame's camera pose becomes what WebXR would give
// (`XRView.transform.matrix`: column-major, OpenGL camera axes, in the reference space = the
// app's odometry frame), goes to a QuadLoc tracking session with its detections, and the
// answer's `world_from_odom` anchors the map in the scene: the map's ellipsoids are drawn in
// three.js where the map sits in the app's space, with the odometry trajectory and the camera.
//
// Query parameters: map (default chess), recording (a URL), fps (0 = as fast as answers come).
import * as THREE from "three";
import {
  QuadLocClient,
  applyWorldFromOdom,
  ellipsoidMatrix,
  invertPose,
  matrixFromXRRigidTransform,
  odomFromCameraFromXRView,
  poseMatrix,
  setObjectPose,
  transformPoint,
  worldFromCameraOpencvToOpengl,
  xrMatrixFromPose,
} from "/dist/index.js";

const params = new URLSearchParams(location.search);
const mapId = params.get("map") ?? "chess";
const recordingUrl = params.get("recording") ?? "/docs/examples/track_chess.json";
const fps = Number(params.get("fps") ?? 0);
const status = document.getElementById("status");
const canvas = document.getElementById("view");
const show = (text, state) => {
  status.textContent = text;
  if (state) status.dataset.state = state;
};

const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setSize(960, 640);
renderer.setClearColor(0x111111);
const scene = new THREE.Scene(); // the scene's frame is the XR reference space (odometry)
scene.add(new THREE.AmbientLight(0xffffff, 0.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.2);
sun.position.set(2, 3, 4);
scene.add(sun);
const viewer = new THREE.PerspectiveCamera(50, 960 / 640, 0.05, 100);

async function main() {
  const client = new QuadLocClient({ baseUrl: location.origin });
  const recording = await (await fetch(recordingUrl)).json();
  const map = await client.exportMap(mapId);

  // The map, in map coordinates, in one group: placed by world_from_odom once tracking.
  const mapGroup = new THREE.Group();
  mapGroup.visible = false;
  scene.add(mapGroup);
  const palette = [0x4e79a7, 0xf28e2b, 0xe15759, 0x76b7b2, 0x59a14f, 0xedc948, 0xb07aa1, 0xff9da7, 0x9c755f];
  const categories = [...new Set(map.objects.map((o) => o.category))];
  for (const obj of map.objects) {
    const color = palette[categories.indexOf(obj.category) % palette.length];
    const mesh = new THREE.Mesh(new THREE.SphereGeometry(1, 24, 16),
      new THREE.MeshStandardMaterial({ color, transparent: true, opacity: 0.75 }));
    setObjectPose(mesh, ellipsoidMatrix(obj));
    mesh.name = obj.object_id;
    mapGroup.add(mesh);
  }

  // The odometry trajectory and the current camera, in the scene (odometry) frame.
  const trail = [];
  const trailLine = new THREE.Line(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0xffffff }));
  scene.add(trailLine);
  const xrCamera = new THREE.PerspectiveCamera(45, 4 / 3, 0.05, 0.3);
  const frustum = new THREE.CameraHelper(xrCamera);
  scene.add(xrCamera, frustum);

  const session = await client.startSession(mapId, { camera: recording.camera, convention: "opengl" });
  let tracking = 0;
  let worldFromOdom = null;
  let lastError = null;
  const frames = recording.frames;
  for (let i = 0; i < frames.length; i++) {
    const f = frames[i];
    // What WebXR hands the app for this frame: the view's pose in the reference space.
    const odomFromCameraGl = worldFromCameraOpencvToOpengl(f.odom_from_camera.matrix);
    const view = { transform: { matrix: xrMatrixFromPose(odomFromCameraGl) } };
    const answer = await session.addFrame({
      detections: f.detections,
      odom_from_camera: odomFromCameraFromXRView(view),
      timestamp: f.timestamp,
      frame_id: f.frame_id,
    });
    const camPose = matrixFromXRRigidTransform(view.transform);
    setObjectPose(xrCamera, camPose);
    trail.push(new THREE.Vector3(camPose[0][3], camPose[1][3], camPose[2][3]));
    trailLine.geometry.setFromPoints(trail);
    if (answer.state === "tracking" && answer.world_from_odom) {
      tracking++;
      worldFromOdom = poseMatrix(answer.world_from_odom);
      applyWorldFromOdom(mapGroup, worldFromOdom);
      mapGroup.visible = true;
      const truth = recording.ground_truth_world_from_camera?.[i];
      if (truth) {
        const centre = transformPoint(worldFromOdom, [camPose[0][3], camPose[1][3], camPose[2][3]]);
        lastError = Math.hypot(centre[0] - truth[0][3], centre[1] - truth[1][3], centre[2] - truth[2][3]);
      }
    }
    frameView(mapGroup, worldFromOdom, map);
    frustum.update();
    renderer.render(scene, viewer);
    show(`frame ${i + 1}/${frames.length}  ${answer.state}${answer.reason ? ` (${answer.reason})` : ""}\n` +
      `tracking ${tracking} frames` + (lastError !== null ? `, camera ${(100 * lastError).toFixed(1)} cm from the truth` : ""));
    if (fps > 0) await new Promise((r) => setTimeout(r, 1000 / fps));
  }
  await session.close();
  status.dataset.frames = String(frames.length);
  status.dataset.tracking = String(tracking);
  status.dataset.objects = String(mapGroup.children.length);
  status.dataset.lastErrorM = lastError === null ? "" : String(lastError);
  status.dataset.painted = String(paintedPixels());
  status.dataset.worldFromOdom = JSON.stringify(worldFromOdom);
  show(status.textContent + "\ndone", "done");
}

/** Points the viewer at the map (once anchored) from above and behind, with the map's up. */
function frameView(mapGroup, worldFromOdom, map) {
  const box = new THREE.Box3();
  if (worldFromOdom) box.setFromObject(mapGroup);
  else box.setFromPoints([new THREE.Vector3(-1, -1, -1), new THREE.Vector3(1, 1, 1)]);
  const centre = box.getCenter(new THREE.Vector3());
  const size = box.getSize(new THREE.Vector3()).length();
  const up = new THREE.Vector3(...(map.up_axis ?? [0, 0, 1]));
  if (worldFromOdom) {
    const odomFromWorld = invertPose(worldFromOdom);
    up.set(...[0, 1, 2].map((r) => odomFromWorld[r][0] * up.x + odomFromWorld[r][1] * up.y + odomFromWorld[r][2] * up.z));
  }
  viewer.up.copy(up.normalize());
  const side = new THREE.Vector3(1, 0, 0).cross(up);
  if (side.lengthSq() < 1e-6) side.set(0, 1, 0);
  viewer.position.copy(centre).addScaledVector(up, 0.6 * size).addScaledVector(side.normalize(), 1.1 * size);
  viewer.lookAt(centre);
}

/** Pixels of the canvas that are not the background (a check that something was drawn). */
function paintedPixels() {
  const gl = renderer.getContext();
  const px = new Uint8Array(gl.drawingBufferWidth * gl.drawingBufferHeight * 4);
  gl.readPixels(0, 0, gl.drawingBufferWidth, gl.drawingBufferHeight, gl.RGBA, gl.UNSIGNED_BYTE, px);
  let n = 0;
  for (let k = 0; k < px.length; k += 4) if (Math.abs(px[k] - 0x11) + Math.abs(px[k + 1] - 0x11) + Math.abs(px[k + 2] - 0x11) > 24) n++;
  return n;
}

main().catch((e) => show(String(e && e.stack || e), "error"));
