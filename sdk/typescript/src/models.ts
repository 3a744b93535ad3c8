/**
 * The wire models: aliases of the types generated from docs/openapi.json
 * (`src/generated/openapi.ts`, `npm run generate`). Nothing here is written by hand but the
 * names: a field added to the API appears in these types when the file is regenerated.
 *
 * Units and frames are the API's (docs/api.md): pixels from the top-left pixel corner, ellipse
 * SEMI-axes and RADIANS, poses `world_from_camera` in metres with `quaternion_wxyz` (scalar
 * first) and a ROW-major `matrix`, OpenCV camera axes unless `convention` says "opengl".
 */
import type { components, paths } from "./generated/openapi.js";

export type { components, paths };
type S = components["schemas"];

// -- requests
/** Pinhole intrinsics fx, fy, cx, cy (px) and the image size width, height (px). */
export type Camera = S["CameraIn"];
/** Image ellipse: centre px, SEMI-axes px (`a` along `angle`), `angle` radians from +x to +y. */
export type Ellipse = S["EllipseIn"];
/** Axis-aligned detection box, px (the server uses its inscribed ellipse). */
export type Box = S["BoxIn"];
/** One detection: `ellipse` or `box`, `label`, optional `sigma` or `log_variance`, `score`. */
export type Detection = S["DetectionIn"];
/** A pose sent to the server: `matrix` (row-major) or a quaternion + `translation_m`. */
export type PoseInput = S["PoseIn"];
/** A prior `world_from_camera` with an optional 6x6 covariance, in `convention` camera axes. */
export type PosePrior = S["PosePriorIn"];
/** The direction gravity pulls (down) in the camera axes of `convention`, with `sigma_deg`. */
export type Gravity = S["GravityIn"];
/** Solver options; absent fields take the server's defaults. */
export type LocalizeOptions = S["LocalizeOptionsIn"];
/** One frame to localize. */
export type LocalizeRequest = S["LocalizeRequest"];
/** Several frames, solved in order against one map version. */
export type BatchLocalizeRequest = S["BatchLocalizeRequest"];
/** Body of `POST /v1/maps/{map_id}/sessions`. */
export type SessionCreate = S["SessionCreate"];
/** Tracking-session options (window, smoother, odometry drift model). */
export type SessionOptions = S["SessionOptionsIn"];
/** One tracking frame: detections + the app's `odom_from_camera` + `timestamp` (s). */
export type SessionFrame = S["SessionFrameIn"];

// -- answers
/** A returned pose: quaternions both orders, `translation_m`, row- and column-major matrices. */
export type Pose = S["PoseOut"];
/** 6x6 covariance, `order` [omega_x, omega_y, omega_z, v_x, v_y, v_z], camera (body) frame. */
export type Covariance = S["CovarianceOut"];
/** A detection matched to a map object. */
export type Inlier = S["InlierOut"];
/** A candidate pose of an answer that is not localized (or ambiguous, answered "best"). */
export type Alternative = S["AlternativeOut"];
/** The answer for one frame; `localized: false` with a `reason` is a normal answer. */
export type LocalizeResponse = S["LocalizeResponse"];
/** The answers of a batch, in the order of its frames. */
export type BatchLocalizeResponse = S["BatchLocalizeResponse"];
/** A map's latest version, as listed. */
export type MapSummary = S["MapSummaryOut"];
/** One stored version of a map. */
export type MapVersion = S["MapVersionOut"];
/** A stored map version with its document (`map`), plus the response's `ETag` (`etag`). */
export type MapRecord = S["MapOut"] & { etag: string | null };
/** A map document (docs/maps.md, format quadloc.map/1). */
export type MapDocument = Record<string, unknown>;
/** A tracking session. */
export type SessionInfo = S["SessionOut"];
/** One tracking frame's answer: `state`, `world_from_camera`, `world_from_odom`, ... */
export type SessionFrameResult = S["SessionFrameOut"];
/** A map version's own calibration (`POST` / `GET /v1/maps/{id}/calibration`). */
export type Calibration = S["CalibrationOut"];
/** A map-building job (`GET /v1/build-jobs/{job_id}`). */
export type BuildJob = S["BuildJobOut"];
/** `/healthz` and `/readyz` answers. */
export type Health = S["HealthOut"];
/** An RFC 9457 problem document (application/problem+json). */
export type Problem = S["Problem"];
/** One invalid field of a request: `field` is a path such as `detections[2].ellipse.a`. */
export type ProblemField = S["ProblemField"];

/** The nine refinement metrics (`LocalizeOptions.metric`), plus "none" (no refinement). */
export type Metric = NonNullable<LocalizeOptions["metric"]>;
