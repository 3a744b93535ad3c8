// GENERATED FILE: do not edit. `npm run generate` (in sdk/typescript) rewrites it from
// docs/openapi.json with openapi-typescript 7.13.0.
// openapi-sha256: 0bb554bd25224c1e8e1d86cf61d4a35b3c7d1ca8b50499c88b9572798bbcaba9

export interface paths {
    "/v1/maps/{map_id}/localize": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        get?: never;
        put?: never;
        /**
         * Localize one frame
         * @description Matches the frame's detections to the map's ellipsoids (label-constrained RANSAC with P3P/P2E, then refinement with the chosen metric) and returns the camera pose `world_from_camera`, its covariance and a confidence. `localized: false` with a `reason` is a normal 200 answer. With `Accept: image/svg+xml` the answer is the frame drawn instead (detections, the map's ellipsoids projected at the returned pose, inliers vs outliers, IoU and cost per match; the JSON answer inside `<metadata>`).
         */
        post: operations["localize_frame_v1_maps__map_id__localize_post"];
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/maps/{map_id}/localize:batch": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        get?: never;
        put?: never;
        /**
         * Localize several frames
         * @description Frames are solved in order against one map version (bounded count: QUADLOC_MAX_BATCH_FRAMES). Errors name the frame: `frames[3].detections[0]...`. The whole batch has a time budget (QUADLOC_BATCH_TIME_BUDGET_MS, queue waits included): frames not started when it runs out answer `localized: false` with reason `time_budget_exceeded`; frames already solved are kept.
         */
        post: operations["localize_batch_v1_maps__map_id__localize_batch_post"];
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/maps": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        /** List maps (latest versions) */
        get: operations["list_maps_v1_maps_get"];
        put?: never;
        /**
         * Create a map (version 1)
         * @description Body: the map document (docs/maps.md). `version` in the body is ignored: a new map is version 1. Answers 201 with the stored map, its `ETag` and `Location`; 409 if the id is taken; 422 naming every invalid field.
         */
        post: operations["create_map_v1_maps_post"];
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/maps:import-chess": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        get?: never;
        put?: never;
        /**
         * Create a map from the Chess scene format
         * @description Body: the Chess format (`category_id_to_label`, `objects[]` with `ellipsoid {axes, R, center}`; world +Z up). The map id and name come from the query.
         */
        post: operations["import_chess_map_v1_maps_import_chess_post"];
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/maps/{map_id}": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        /**
         * Get a map (latest or a given version)
         * @description The response carries `ETag: "<content_hash>"`; send it back in `If-Match` to update. Old versions stay readable with `?version=n`.
         */
        get: operations["get_map_v1_maps__map_id__get"];
        /**
         * Update a map (new version)
         * @description Body: the full map document (its `map_id` must equal the path's). Requires `If-Match` with the latest version's ETag. Checked in this order: the body (invalid -> 422 naming the fields), then `If-Match` (missing or `*` -> 428), the map (absent -> 404), the ETag (stale -> 412, the current ETag is in the response); a lost race -> 409. Answers 200 with the new version and its ETag.
         */
        put: operations["update_map_v1_maps__map_id__put"];
        post?: never;
        /**
         * Delete a map (all its versions)
         * @description Deletes every version. The server's default map (QUADLOC_DEFAULT_MAP_ID, `chess` unless configured) is refused with 409: /readyz checks it, so deleting it would take every replica out of service. Update it with PUT instead.
         */
        delete: operations["delete_map_v1_maps__map_id__delete"];
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/maps/{map_id}/versions": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        /**
         * List a map's versions
         * @description Every stored version (immutable, readable with `GET /v1/maps/{map_id}?version=n`), ascending, with its content hash (the ETag) and creation time.
         */
        get: operations["list_map_versions_v1_maps__map_id__versions_get"];
        put?: never;
        post?: never;
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/maps:build": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        get?: never;
        put?: never;
        /**
         * Build a map from a recording (asynchronous job)
         * @description Body: a recording (docs/map_building.md). Answers 202 with the job and `Location: /v1/build-jobs/{job_id}`; poll it for progress and the result. 422 names every invalid field (`frames` beyond QUADLOC_MAX_BUILD_FRAMES); 413 beyond QUADLOC_MAX_BUILD_BODY_BYTES (both: 2,000 frames / 4 MB when builds run in the API process, 10,000 / 32 MB with build workers; docs/deployment.md, "Build limits"); 428/412 for If-Match on an existing map; 503 + Retry-After when this replica has too many builds queued.
         */
        post: operations["start_build_v1_maps_build_post"];
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/build-jobs/{job_id}": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        /**
         * A map-building job
         * @description Status, stage, percent, objects found; the map version and the report when it succeeded, `error {reason, detail}` when it failed. A job whose runner stopped reporting (replica restarted) is marked failed (`runner_lost`). A job belongs to the API key that started it: other keys get 404 (an `admin` key sees all).
         */
        get: operations["get_build_job_v1_build_jobs__job_id__get"];
        put?: never;
        post?: never;
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/maps/{map_id}/calibration": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        /** A map version's calibration (404 when it has none: the shipped one applies) */
        get: operations["get_calibration_v1_maps__map_id__calibration_get"];
        put?: never;
        /**
         * Calibrate a map version from a recording's held-out frames
         * @description Body: the recording the map was built from, with `holdout_every` (the frames held out of the build, their app poses the reference). Fits the covariance scale and the confidence model on them, reports mean NEES and the confidence calibration error before / after on them (after: cross-fitted, each frame by a fit on the other folds), and stores the calibration with the map version: localize and tracking sessions use it for the calibration key it was fitted for. Synchronous: two solves per held-out frame (1,000 held-out frames in about 25 s measured; the body limit, 2 MB by default, bounds a recording to about 2,500 frames, so at most about 1,250 held out). 422 when the recording holds no frame out or too few localize (at least 20 must: the inline example shows the body's form only and gets that 422; docs/map_building.md calibrates the shipped example recording).
         */
        post: operations["calibrate_map_v1_maps__map_id__calibration_post"];
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/healthz": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        /**
         * Liveness probe
         * @description 200 while the process serves requests (no dependency checked).
         */
        get: operations["healthz_healthz_get"];
        put?: never;
        post?: never;
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/readyz": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        /**
         * Readiness probe
         * @description 200 when the database answers and the default map compiles; 503 problem otherwise.
         */
        get: operations["readyz_readyz_get"];
        put?: never;
        post?: never;
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/metrics": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        /** Prometheus metrics */
        get: operations["metrics_metrics_get"];
        put?: never;
        post?: never;
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/maps/{map_id}/sessions": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        get?: never;
        put?: never;
        /**
         * Start a tracking session
         * @description The session belongs to the API key that created it: other keys get 404 (an `admin` key sees all). 429 `session-quota` when this key holds `QUADLOC_MAX_SESSIONS_PER_KEY` live sessions on this replica, 503 `session-capacity` when the replica holds `QUADLOC_MAX_SESSIONS`.
         */
        post: operations["create_session_v1_maps__map_id__sessions_post"];
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/sessions/{session_id}": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        /** Describe a session */
        get: operations["get_session_v1_sessions__session_id__get"];
        put?: never;
        post?: never;
        /** End a session */
        delete: operations["delete_session_v1_sessions__session_id__delete"];
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
    "/v1/sessions/{session_id}/frames": {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        get?: never;
        put?: never;
        /**
         * Add frames to a session (one, or a recording in time order)
         * @description Body: one frame object, or `{"frames": [...]}` (batch, at most 900). Frames are validated all before any is fused: an error names `frames[i]....` and leaves the session unchanged.
         */
        post: operations["add_frames_v1_sessions__session_id__frames_post"];
        delete?: never;
        options?: never;
        head?: never;
        patch?: never;
        trace?: never;
    };
}
export type webhooks = Record<string, never>;
export interface components {
    schemas: {
        /**
         * AlternativeOut
         * @description A distinct candidate pose of a verified answer that is not localized (ambiguous, low
         *     confidence, gravity mismatch) or of an ambiguous one answered with on_ambiguity 'best'.
         */
        AlternativeOut: {
            world_from_camera: components["schemas"]["PoseOut"];
            /**
             * Confidence
             * @description P(within 10 cm and 5 deg).
             */
            confidence: number;
            /** N Inliers */
            n_inliers: number;
            /**
             * Score
             * @description Sum of the inliers' IoUs.
             */
            score: number;
            /**
             * Zone
             * @description The map zone (docs/maps.md) holding the most of this pose's inlier objects; ties: the zone with the fewest objects (a room before its floor), then the first in the map's `zones`. null when the map has no zones or none holds an inlier.
             */
            zone?: string | null;
        };
        /**
         * BatchLocalizeRequest
         * @description Several frames (bounded count) localized in order with the same map version.
         */
        BatchLocalizeRequest: {
            /** Frames */
            frames: components["schemas"]["LocalizeRequest"][];
        };
        /** BatchLocalizeResponse */
        BatchLocalizeResponse: {
            /** Map Id */
            map_id: string;
            /** Map Version */
            map_version: number;
            /** Results */
            results: components["schemas"]["LocalizeResponse"][];
        };
        /**
         * BoxIn
         * @description Axis-aligned box in px; the detection becomes its inscribed ellipse.
         */
        BoxIn: {
            /** Xmin */
            xmin: number;
            /** Ymin */
            ymin: number;
            /** Xmax */
            xmax: number;
            /** Ymax */
            ymax: number;
        };
        /** BuildCounts */
        BuildCounts: {
            /** Frames */
            frames: number;
            /** Detections */
            detections: number;
            /** Objects */
            objects: number;
            /** Rejected Detections */
            rejected_detections: number;
        };
        /**
         * BuildErrorOut
         * @description Why a build job failed.
         */
        BuildErrorOut: {
            /**
             * Reason
             * @description invalid_recording, time_budget_exceeded, no_objects, map_exists, version_conflict, map_not_found, store_unavailable, busy, runner_lost or internal_error.
             */
            reason: string;
            /** Detail */
            detail: string;
        };
        /**
         * BuildJobOut
         * @description A map-building job.
         */
        BuildJobOut: {
            /** Job Id */
            job_id: string;
            /** Map Id */
            map_id: string;
            /**
             * Status
             * @enum {string}
             */
            status: "queued" | "running" | "succeeded" | "failed";
            /**
             * Stage
             * @description queued, associating, refining, saving, done or failed
             */
            stage: string;
            /**
             * Percent
             * @description Progress, 0-100.
             */
            percent: number;
            /** Objects Found */
            objects_found: number;
            /**
             * Base Version
             * @description Version the build replaces (If-Match), null for a new map.
             */
            base_version: number | null;
            /**
             * Map Version
             * @description Version created (succeeded jobs).
             */
            map_version: number | null;
            /** @description Why it failed (failed jobs). */
            error: components["schemas"]["BuildErrorOut"] | null;
            /** @description Association and quality report. */
            report: components["schemas"]["BuildReport"] | null;
            /** Created At */
            created_at: string;
            /** Updated At */
            updated_at: string;
        };
        /**
         * BuildReport
         * @description The report of one build (module docstring).
         */
        BuildReport: {
            /** Objects */
            objects: components["schemas"]["ObjectReport"][];
            /** Dropped Objects */
            dropped_objects: components["schemas"]["DroppedObject"][];
            /** Rejected Detections */
            rejected_detections: components["schemas"]["RejectedDetection"][];
            counts: components["schemas"]["BuildCounts"];
            /** @description None when no object was found. */
            refinement: components["schemas"]["RefinementReport"] | null;
            /**
             * Timings S
             * @description association, refinement, total (s).
             */
            timings_s: {
                [key: string]: number;
            };
            /**
             * Warnings
             * @description What the user should know about this map.
             */
            warnings?: string[];
        };
        /**
         * CalibrationOut
         * @description A map version's own calibration (used by localize for the calibration key it was fitted
         *     for; other keys keep the shipped constants).
         */
        CalibrationOut: {
            /** Map Id */
            map_id: string;
            /** Map Version */
            map_version: number;
            /**
             * Key
             * @description Calibration key fitted (metric, ':unit_weights' without sigma on every detection).
             */
            key: string;
            /**
             * Fit Frames
             * @description Held-out frames the stored fit used (all of them; `after` is cross-fitted: each frame reported by a fit on the other folds).
             */
            fit_frames: number;
            /**
             * Covariance Scale
             * @description Fitted k of the key (shipped value in `shipped_covariance_scale`).
             */
            covariance_scale: number;
            /** Shipped Covariance Scale */
            shipped_covariance_scale: number;
            /** S2 Floor */
            s2_floor: number;
            /**
             * Min Confidence
             * @description Default min_confidence with this calibration.
             */
            min_confidence: number;
            /** @description Held-out frames, shipped constants. */
            before: components["schemas"]["CalibrationQualityOut"];
            /** @description Held-out frames, each with a calibration fitted without its fold (5 folds of 25-frame chunks). */
            after: components["schemas"]["CalibrationQualityOut"];
        };
        /**
         * CalibrationQualityOut
         * @description How well covariance and confidence describe the errors on the report frames.
         */
        CalibrationQualityOut: {
            /**
             * Frames
             * @description Report frames solved.
             */
            frames: number;
            /**
             * Localized
             * @description Of them localized (min_confidence 0).
             */
            localized: number;
            /**
             * Nees Frames
             * @description Localized within 10 cm of the reference: the NEES frames.
             */
            nees_frames: number;
            /**
             * Mean Nees
             * @description Mean NEES (6 = well scaled; the target band is [4, 9]).
             */
            mean_nees: number | null;
            /**
             * Calibration Error
             * @description Expected calibration error of `confidence` (10 bins) against success = within 10 cm and 5 deg of the reference.
             */
            calibration_error: number | null;
            /**
             * Calibration Error Floor
             * @description The calibration error a perfectly calibrated `confidence` would show on these answers by sampling alone (mean over 200 draws of outcomes from the confidences): an error near it is as good as these frames can tell.
             */
            calibration_error_floor?: number | null;
            /**
             * Calibration Error Sd
             * @description Sampling standard deviation of `calibration_error`: moving-block bootstrap over blocks of 25 consecutive frames (their outcomes are correlated); null with fewer than 50 localized frames.
             */
            calibration_error_sd?: number | null;
            /** Mean Confidence */
            mean_confidence: number | null;
            /** Success Rate */
            success_rate: number | null;
        };
        /**
         * CameraIn
         * @description Pinhole intrinsics (px, zero skew, undistorted detections) and image size (px).
         */
        CameraIn: {
            /** Fx */
            fx: number;
            /** Fy */
            fy: number;
            /** Cx */
            cx: number;
            /** Cy */
            cy: number;
            /** Width */
            width: number;
            /** Height */
            height: number;
        };
        /** CovarianceOut */
        CovarianceOut: {
            /**
             * Order
             * @description Row/column order of `matrix`.
             * @default [
             *       "omega_x",
             *       "omega_y",
             *       "omega_z",
             *       "v_x",
             *       "v_y",
             *       "v_z"
             *     ]
             */
            order?: string[];
            /**
             * Frame
             * @default camera (body) frame, right perturbation T*exp(xi), omega in rad, v in m
             */
            frame?: string;
            /** Matrix */
            matrix: number[][];
        };
        /**
         * DetectionIn
         * @description One detected object: exactly one of `ellipse` or `box`, its label, optional uncertainty
         *     (`sigma` or `log_variance`, not both) and optional detector `score`.
         */
        DetectionIn: {
            ellipse?: components["schemas"]["EllipseIn"] | null;
            box?: components["schemas"]["BoxIn"] | null;
            /**
             * Label
             * @description Category label of the map.
             */
            label: string;
            /**
             * Sigma
             * @description Predicted uncertainty (> 0); cost weight 1/sigma.
             */
            sigma?: number | null;
            /**
             * Log Variance
             * @description alpha = log sigma^2; sigma = exp(alpha/2).
             */
            log_variance?: number | null;
            /**
             * Score
             * @description Detector score.
             */
            score?: number | null;
        };
        /**
         * DetectionRef
         * @description A detection of the recording: its frame (id and position) and its position in it.
         */
        DetectionRef: {
            /** Frame Id */
            frame_id: string | null;
            /** Frame Index */
            frame_index: number;
            /** Detection Index */
            detection_index: number;
        };
        /**
         * DroppedObject
         * @description An object reconstructed but left out of the map.
         */
        DroppedObject: {
            /** Object Id */
            object_id: string;
            /** Label */
            label: string;
            /**
             * Reason
             * @description degenerate_shape, rarely_seen, unconstrained or center_unconstrained.
             */
            reason: string;
            /** Detail */
            detail: string;
            /** N Views */
            n_views: number;
            /** Semi Axes M */
            semi_axes_m: number[];
        };
        /**
         * EllipseIn
         * @description Image ellipse: centre px, semi-axes px, angle radians (from +x towards +y).
         */
        EllipseIn: {
            /**
             * Cx
             * @description Centre x (px).
             */
            cx: number;
            /**
             * Cy
             * @description Centre y (px).
             */
            cy: number;
            /**
             * A
             * @description Semi-axis along `angle` (px).
             */
            a: number;
            /**
             * B
             * @description Other semi-axis (px).
             */
            b: number;
            /**
             * Angle
             * @description Direction of semi-axis `a`, radians from +x towards +y.
             * @default 0
             */
            angle?: number;
        };
        /**
         * GravityIn
         * @description Optional gravity direction measured by the client (e.g. ARKit/ARCore/CoreMotion gravity):
         *     a factor on the pose's tilt (roll, pitch) in the refinement; candidates whose tilt
         *     disagrees with it are dropped, and an answer that disagrees is not localized (reason
         *     `gravity_mismatch`). The map's `up_axis` gives the world's up.
         */
        GravityIn: {
            /**
             * Direction
             * @description Direction gravity pulls (DOWN, toward the ground) in the camera axes of `convention`; any positive length. An accelerometer at rest measures the opposite (up): negate it.
             */
            direction: number[];
            /**
             * Sigma Deg
             * @description Angular uncertainty (1 sigma per tilt axis, degrees).
             * @default 2
             */
            sigma_deg?: number;
            /**
             * Convention
             * @description Camera axes of `direction` (opencv or opengl).
             * @default opencv
             * @enum {string}
             */
            convention?: "opencv" | "opengl";
        };
        /** HealthOut */
        HealthOut: {
            /** Status */
            status: string;
            /** Checks */
            checks?: {
                [key: string]: string;
            };
        };
        /**
         * HintIn
         * @description Optional coarse hint of where the camera is: a position with a large uncertainty (a GPS /
         *     Wi-Fi / beacon fix, the app's last known position) or the objects of a zone (a room, a
         *     floor). It weights the search of a large map and settles a tie between places in its
         *     favour; it never makes an answer win that the detections do not support.
         */
        HintIn: {
            /**
             * Position
             * @description The camera's position in the map's world frame, metres.
             */
            position?: number[] | null;
            /**
             * Sigma M
             * @description 1-sigma uncertainty of `position` (m).
             */
            sigma_m?: number | null;
            /**
             * Object Ids
             * @description The objects of the zone the camera is in (ids of the map's objects).
             */
            object_ids?: string[] | null;
            /**
             * Zone Id
             * @description The zone the camera is in (a `zone_id` of the map's `zones`): stands for that zone's objects.
             */
            zone_id?: string | null;
        };
        /** InlierOut */
        InlierOut: {
            /** Detection Index */
            detection_index: number;
            /** Object Id */
            object_id: string;
            /** Iou */
            iou: number;
            /** Cost */
            cost: number;
        };
        /**
         * LegacyDetectionIn
         * @description A detection of the deprecated form: ``box`` may be an array ``[xmin, ymin, xmax, ymax]``
         *     and ``track_id`` an integer.
         */
        LegacyDetectionIn: {
            ellipse?: components["schemas"]["EllipseIn"] | null;
            box?: components["schemas"]["BoxIn"] | null;
            /**
             * Label
             * @description Category label: the built object's category.
             */
            label: string;
            /**
             * Sigma
             * @description Predicted uncertainty (> 0); cost weight 1/sigma.
             */
            sigma?: number | null;
            /**
             * Log Variance
             * @description alpha = log sigma^2; sigma = exp(alpha/2).
             */
            log_variance?: number | null;
            /**
             * Score
             * @description Detector score.
             */
            score?: number | null;
            /**
             * Track Id
             * @description The detector's / tracker's object track.
             */
            track_id?: string | null;
        };
        /**
         * LegacyFrameIn
         * @description A frame of the deprecated form.
         */
        LegacyFrameIn: {
            /**
             * Frame Id
             * @description Defaults to the frame's position.
             */
            frame_id?: string | null;
            /** @description The app's camera pose (m), in the recording's `convention`. */
            world_from_camera: components["schemas"]["PoseIn"];
            /**
             * Timestamp
             * @description Client clock (s); informative.
             */
            timestamp?: number | null;
            /** Detections */
            detections?: components["schemas"]["LegacyDetectionIn"][];
        };
        /**
         * LegacyRecordingIn
         * @deprecated
         * @description DEPRECATED form of earlier releases (``intrinsics``, boxes as arrays); read for one more
         *     release, its build report carries a deprecation warning.
         */
        LegacyRecordingIn: {
            /**
             * Name
             * @description Name of the built map.
             * @default Built map
             */
            name?: string;
            /**
             * Up Axis
             * @description World up direction of the app's world frame.
             * @default [
             *       0,
             *       0,
             *       1
             *     ]
             */
            up_axis?: number[];
            /**
             * Size Priors
             * @description Label -> prior on its objects' semi-axes.
             */
            size_priors?: {
                [key: string]: components["schemas"]["SizePriorIn"];
            };
            /**
             * Refine Camera Poses
             * @description Refine the app's camera poses with the objects (tied by their relative poses with `odometry_noise`).
             * @default true
             */
            refine_camera_poses?: boolean;
            odometry_noise?: components["schemas"]["OdometryNoiseIn"];
            /**
             * Holdout Every
             * @description Hold every k-th frame (positions k-1, 2k-1, ...) out of the build: those frames, with their app poses as reference, calibrate the map (POST /v1/maps/{map_id}/calibration with the same recording).
             */
            holdout_every?: number | null;
            intrinsics: components["schemas"]["CameraIn"];
            /** Frames */
            frames: components["schemas"]["LegacyFrameIn"][];
        };
        /**
         * LocalizeOptionsIn
         * @description Solver options; omitted fields take the server defaults (shown).
         */
        LocalizeOptionsIn: {
            /**
             * Metric
             * @description Refinement metric (one of the nine), or 'none': the P3P/P2E pose unrefined (no covariance).
             * @default level_set
             * @enum {string}
             */
            metric?: "iou" | "giou" | "bbox" | "qbbox" | "algebraic" | "frobenius" | "wasserstein" | "bhattacharyya" | "level_set" | "none";
            /**
             * Ransac Max Hypotheses
             * @description RANSAC budget of minimal samples.
             * @default 300
             */
            ransac_max_hypotheses?: number;
            /**
             * Inlier Iou
             * @description IoU threshold for a detection to be an inlier.
             * @default 0.2
             */
            inlier_iou?: number;
            /**
             * Min Inliers
             * @default 2
             */
            min_inliers?: number;
            /**
             * Use Sigma
             * @description Weight costs by 1/sigma (paper eq. 8) when every detection has a sigma (else every weight is 1; docs/api.md).
             * @default true
             */
            use_sigma?: boolean;
            /**
             * Robust
             * @description Robust kernel of the refinement.
             */
            robust?: ("huber" | "cauchy" | "geman_mcclure") | null;
            /**
             * Robust Scale
             * @description Kernel scale (needs `robust`).
             */
            robust_scale?: number | null;
            /**
             * Unknown Label Policy
             * @default ignore
             * @enum {string}
             */
            unknown_label_policy?: "ignore" | "error";
            /**
             * Seed
             * @default 0
             */
            seed?: number | null;
            /**
             * Time Budget Ms
             * @description Solve budget (ms); capped by the server's QUADLOC_SOLVE_TIME_BUDGET_MS.
             */
            time_budget_ms?: number | null;
            /**
             * Max Iterations
             * @description Levenberg-Marquardt iteration cap.
             * @default 50
             */
            max_iterations?: number;
            /**
             * Output Convention
             * @description Camera axes of the returned pose and covariance.
             * @default opencv
             * @enum {string}
             */
            output_convention?: "opencv" | "opengl";
            /**
             * On Ambiguity
             * @description When a distinct pose explains the detections comparably well: 'not_localized' (reason 'ambiguous') or 'best' (the best pose, localized); both list the candidates in `alternatives` with their probabilities.
             * @default not_localized
             * @enum {string}
             */
            on_ambiguity?: "not_localized" | "best";
            /**
             * Min Confidence
             * @description Answers with a lower confidence are returned as not localized (reason 'low_confidence'); null = the calibrated default (docs/api.md).
             */
            min_confidence?: number | null;
        };
        /**
         * LocalizeRequest
         * @description One frame to localize against the map.
         */
        LocalizeRequest: {
            camera: components["schemas"]["CameraIn"];
            /** Detections */
            detections: components["schemas"]["DetectionIn"][];
            prior?: components["schemas"]["PosePriorIn"] | null;
            gravity?: components["schemas"]["GravityIn"] | null;
            hint?: components["schemas"]["HintIn"] | null;
            /**
             * Frame Id
             * @description Echoed back.
             */
            frame_id?: string | null;
            /**
             * Timestamp
             * @description Echoed back (client clock, s).
             */
            timestamp?: number | null;
            options?: components["schemas"]["LocalizeOptionsIn"];
        };
        /**
         * LocalizeResponse
         * @description `localized: false` with a `reason` is a normal answer (HTTP 200), not an error.
         */
        LocalizeResponse: {
            /** Localized */
            localized: boolean;
            /**
             * Reason
             * @description Why not localized: too_few_detections, no_label_match, no_hypothesis_above_inlier_threshold, refinement_diverged, time_budget_exceeded, ambiguous, low_confidence, gravity_mismatch, numerical_failure; null when localized.
             */
            reason: string | null;
            world_from_camera: components["schemas"]["PoseOut"] | null;
            covariance: components["schemas"]["CovarianceOut"] | null;
            /**
             * Confidence
             * @description Probability that the pose is within 0.10 m and 5 deg of the truth (calibrated on simulated frames, docs/api.md).
             */
            confidence: number;
            /** Inliers */
            inliers: components["schemas"]["InlierOut"][];
            /** Metric */
            metric: string;
            /** Hypotheses Evaluated */
            hypotheses_evaluated: number;
            /** Used Prior */
            used_prior: boolean;
            /**
             * Refinement Status
             * @description Status of the last pose refinement: converged, max_iterations, time_budget (the solve budget cut it short: the pose is less refined), diverged, invalid_projection; null when no refinement ran.
             */
            refinement_status?: string | null;
            /**
             * Pose Source
             * @description Which path won: 'prior' (the refined client prior) or 'ransac'; null when not localized.
             */
            pose_source?: ("prior" | "ransac") | null;
            /**
             * Zone
             * @description The map zone (docs/maps.md) holding the most of this pose's inlier objects; ties: the zone with the fewest objects (a room before its floor), then the first in the map's `zones`. null when the map has no zones or none holds an inlier. Set whenever the answer has a pose or its best candidate (localized, or not localized with `alternatives`).
             */
            zone?: string | null;
            /**
             * Alternatives
             * @description Verified but not localized (ambiguous, low_confidence, gravity_mismatch), or localized with on_ambiguity 'best' on an ambiguous frame: the distinct candidate poses, most probable first, each with its probability (`confidence`).
             */
            alternatives?: components["schemas"]["AlternativeOut"][];
            /** Map Id */
            map_id: string;
            /** Map Version */
            map_version: number;
            /** Timings Ms */
            timings_ms: {
                [key: string]: number;
            };
            /** Frame Id */
            frame_id?: string | null;
            /** Timestamp */
            timestamp?: number | null;
        };
        /** MapListOut */
        MapListOut: {
            /** Maps */
            maps: components["schemas"]["MapSummaryOut"][];
        };
        /**
         * MapOut
         * @description A stored map version: its metadata and the map document (docs/maps.md format).
         */
        MapOut: {
            /** Map Id */
            map_id: string;
            /** Version */
            version: number;
            /**
             * Content Hash
             * @description sha256 of the canonical map content (the ETag).
             */
            content_hash: string;
            /** Created At */
            created_at?: string | null;
            /**
             * Map
             * @description The map in the documented JSON format.
             */
            map: {
                [key: string]: unknown;
            };
        };
        /** MapSummaryOut */
        MapSummaryOut: {
            /** Map Id */
            map_id: string;
            /** Name */
            name: string;
            /** Version */
            version: number;
            /** Content Hash */
            content_hash: string;
            /** Updated At */
            updated_at?: string | null;
        };
        /** MapVersionOut */
        MapVersionOut: {
            /** Version */
            version: number;
            /**
             * Content Hash
             * @description sha256 of the version's canonical content (its ETag).
             */
            content_hash: string;
            /** Created At */
            created_at?: string | null;
        };
        /**
         * MapVersionsOut
         * @description Every stored version of a map, ascending (the last one is the latest).
         */
        MapVersionsOut: {
            /** Map Id */
            map_id: string;
            /** Versions */
            versions: components["schemas"]["MapVersionOut"][];
        };
        /**
         * ObjectQualityReport
         * @description How well the views determine an object (``quadloc.maps.building.joint``).
         */
        ObjectQualityReport: {
            /** N Views */
            n_views: number;
            /**
             * View Spread Deg
             * @description Largest angle between two viewing rays (deg).
             */
            view_spread_deg: number;
            /** Residual Cost */
            residual_cost: number;
            /**
             * Rms Level Residual
             * @description RMS level-set residual of its views.
             */
            rms_level_residual: number;
            /**
             * Log Semi Axis Std
             * @description Std of log(semi-axis), per axis.
             */
            log_semi_axis_std: number[];
            /**
             * Center Std M
             * @description Largest std of the centre along a direction (m).
             */
            center_std_m: number;
            /**
             * Unconstrained Axes
             * @description Semi-axes the views do not constrain.
             */
            unconstrained_axes: number[];
            /** Semi Axes M */
            semi_axes_m: number[];
        };
        /**
         * ObjectReport
         * @description An object of the built map and the detections it was built from.
         */
        ObjectReport: {
            /** Object Id */
            object_id: string;
            /** Label */
            label: string;
            /**
             * Association
             * @description How its detections were grouped (track or geometry).
             */
            association: string;
            /** Detections */
            detections: components["schemas"]["DetectionRef"][];
            quality: components["schemas"]["ObjectQualityReport"];
        };
        /**
         * OdometryNoiseIn
         * @description Noise of the app's poses between two recorded frames, a random walk (defaults shown;
         *     ``quadloc.maps.building.recording.OdometryNoise`` states the model).
         */
        OdometryNoiseIn: {
            /**
             * Rotation Rad Per Sqrt M
             * @default 0.005
             */
            rotation_rad_per_sqrt_m?: number;
            /**
             * Translation M Per Sqrt M
             * @default 0.01
             */
            translation_m_per_sqrt_m?: number;
            /**
             * Rotation Rad Per Step
             * @description Floor per frame step (rad), > 0.
             * @default 0.0005
             */
            rotation_rad_per_step?: number;
            /**
             * Translation M Per Step
             * @description Floor per frame step (m), > 0.
             * @default 0.001
             */
            translation_m_per_step?: number;
        };
        /**
         * PlaceCandidateOut
         * @description A place the session's walk may be in (docs/tracking.md, "Places").
         */
        PlaceCandidateOut: {
            /** @description This frame's camera pose if the walk is in this place. */
            world_from_camera: components["schemas"]["PoseOut"];
            /**
             * Probability
             * @description Posterior probability that the walk is in this place (the rest: in none of those listed).
             */
            probability: number;
            /**
             * Zone
             * @description The map zone of the objects this place matched (the zone rule of `zone`); null without zones.
             */
            zone?: string | null;
        };
        /**
         * PoseIn
         * @description A ``world_from_camera`` pose: `quaternion_wxyz` (or `quaternion_xyzw`) + `translation_m`,
         *     or a 4x4 `matrix` given as a list of ROWS (row-major).
         */
        PoseIn: {
            /**
             * Quaternion Wxyz
             * @description Unit quaternion (w, x, y, z): |q| = 1 within 1e-6, else 422.
             */
            quaternion_wxyz?: number[] | null;
            /**
             * Quaternion Xyzw
             * @description The same unit quaternion scalar LAST (ARKit/ARCore/Unity order); give it instead of `quaternion_wxyz`.
             */
            quaternion_xyzw?: number[] | null;
            /** Translation M */
            translation_m?: number[] | null;
            /**
             * Matrix
             * @description 4x4 homogeneous matrix [[R, t], [0, 0, 0, 1]] given as a list of 4 ROWS (row-major): R orthonormal within 1e-6 with det +1, last row [0, 0, 0, 1], else 422.
             */
            matrix?: number[][] | null;
        };
        /**
         * PoseOut
         * @description The camera's pose in the map frame (``world_from_camera``).
         */
        PoseOut: {
            /**
             * Quaternion Wxyz
             * @description Unit quaternion (w, x, y, z), w >= 0.
             */
            quaternion_wxyz: number[];
            /**
             * Quaternion Xyzw
             * @description The same quaternion scalar LAST (x, y, z, w): the order of ARKit/simd, ARCore, Unity and ROS.
             */
            quaternion_xyzw: number[];
            /**
             * Translation M
             * @description Camera centre in the map frame (m).
             */
            translation_m: number[];
            /**
             * Matrix
             * @description 4x4 homogeneous world_from_camera, ROW-major: a list of 4 rows, `matrix[r][c]`.
             */
            matrix: number[][];
            /**
             * Matrix Column Major
             * @description The same 4x4 as 16 numbers in COLUMN-major order (column 0 top to bottom, then column 1...): simd_float4x4(columns:), Unity Matrix4x4, OpenGL/glm, three.js Matrix4.fromArray.
             */
            matrix_column_major: number[];
            /**
             * Convention
             * @description Camera axes of this pose.
             * @enum {string}
             */
            convention: "opencv" | "opengl";
        };
        /**
         * PosePriorIn
         * @description Optional pose prior (e.g. from the AR session's tracking).
         */
        PosePriorIn: {
            world_from_camera: components["schemas"]["PoseIn"];
            /**
             * Covariance
             * @description Optional 6x6 covariance in GTSAM Pose3 tangent order [omega_x, omega_y, omega_z, v_x, v_y, v_z], camera (body) frame, right perturbation T*exp(xi), omega in rad, v in m. Symmetric positive definite. With it the prior is also a soft factor of the refinement.
             */
            covariance?: number[][] | null;
            /**
             * Convention
             * @description Camera axes of this prior (opencv or opengl).
             * @default opencv
             * @enum {string}
             */
            convention?: "opencv" | "opengl";
        };
        /**
         * Problem
         * @description RFC 9457 problem details (media type application/problem+json).
         */
        Problem: {
            /** Type */
            type: string;
            /** Title */
            title: string;
            /** Status */
            status: number;
            /** Detail */
            detail: string;
            /** Instance */
            instance?: string | null;
            /** Errors */
            errors?: components["schemas"]["ProblemField"][];
        };
        /** ProblemField */
        ProblemField: {
            /** Field */
            field: string;
            /** Message */
            message: string;
        };
        /**
         * RecordingDetectionIn
         * @description A detection as for localize, plus an optional ``track_id``: detections of one track (and
         *     label) are one object.
         */
        RecordingDetectionIn: {
            ellipse?: components["schemas"]["EllipseIn"] | null;
            box?: components["schemas"]["BoxIn"] | null;
            /**
             * Label
             * @description Category label: the built object's category.
             */
            label: string;
            /**
             * Sigma
             * @description Predicted uncertainty (> 0); cost weight 1/sigma.
             */
            sigma?: number | null;
            /**
             * Log Variance
             * @description alpha = log sigma^2; sigma = exp(alpha/2).
             */
            log_variance?: number | null;
            /**
             * Score
             * @description Detector score.
             */
            score?: number | null;
            /**
             * Track Id
             * @description The detector's / tracker's object track.
             */
            track_id?: string | null;
        };
        /**
         * RecordingFrameIn
         * @description One recorded frame: the app's camera pose and the frame's detections.
         */
        RecordingFrameIn: {
            /**
             * Frame Id
             * @description Defaults to the frame's position.
             */
            frame_id?: string | null;
            /** @description The app's camera pose (m), in the recording's `convention`. */
            world_from_camera: components["schemas"]["PoseIn"];
            /**
             * Timestamp
             * @description Client clock (s); informative.
             */
            timestamp?: number | null;
            /** Detections */
            detections?: components["schemas"]["RecordingDetectionIn"][];
        };
        /**
         * RecordingIn
         * @description A recording: the camera, posed frames with detections, build options.
         */
        RecordingIn: {
            /**
             * Name
             * @description Name of the built map.
             * @default Built map
             */
            name?: string;
            /**
             * Up Axis
             * @description World up direction of the app's world frame.
             * @default [
             *       0,
             *       0,
             *       1
             *     ]
             */
            up_axis?: number[];
            /**
             * Size Priors
             * @description Label -> prior on its objects' semi-axes.
             */
            size_priors?: {
                [key: string]: components["schemas"]["SizePriorIn"];
            };
            /**
             * Refine Camera Poses
             * @description Refine the app's camera poses with the objects (tied by their relative poses with `odometry_noise`).
             * @default true
             */
            refine_camera_poses?: boolean;
            odometry_noise?: components["schemas"]["OdometryNoiseIn"];
            /**
             * Holdout Every
             * @description Hold every k-th frame (positions k-1, 2k-1, ...) out of the build: those frames, with their app poses as reference, calibrate the map (POST /v1/maps/{map_id}/calibration with the same recording).
             */
            holdout_every?: number | null;
            camera: components["schemas"]["CameraIn"];
            /**
             * Convention
             * @description Camera axes of every `world_from_camera` (opengl = ARKit/ARCore).
             * @default opencv
             * @enum {string}
             */
            convention?: "opencv" | "opengl";
            /** Frames */
            frames: components["schemas"]["RecordingFrameIn"][];
        };
        /**
         * RefinementReport
         * @description The joint refinement of objects (and camera poses) over every view.
         */
        RefinementReport: {
            /** Iterations */
            iterations: number;
            /** Initial Error */
            initial_error: number;
            /** Final Error */
            final_error: number;
            /**
             * Stopped Early
             * @description The time budget stopped it: the map holds the estimate at that point.
             */
            stopped_early: boolean;
            /** Camera Poses Refined */
            camera_poses_refined: boolean;
        };
        /**
         * RejectedDetection
         * @description A detection that built no object of the map, and why.
         */
        RejectedDetection: {
            /** Frame Id */
            frame_id: string | null;
            /** Frame Index */
            frame_index: number;
            /** Detection Index */
            detection_index: number;
            /** Label */
            label: string;
            /** Reason */
            reason: string;
        };
        /**
         * SessionCreate
         * @description Start a tracking session on a map.
         */
        SessionCreate: {
            camera: components["schemas"]["CameraIn"];
            /**
             * Convention
             * @description Camera axes of every odom_from_camera, prior and returned world_from_camera of the session (opengl = ARKit/ARCore).
             * @default opencv
             * @enum {string}
             */
            convention?: "opencv" | "opengl";
            options?: components["schemas"]["SessionOptionsIn"];
        };
        /**
         * SessionFrameIn
         * @description One frame: detections as for localize plus the app's odometry pose.
         */
        SessionFrameIn: {
            /** Detections */
            detections?: components["schemas"]["DetectionIn"][];
            /** @description Camera pose in the app's odometry (session) frame, in the session's convention. */
            odom_from_camera: components["schemas"]["PoseIn"];
            /**
             * Timestamp
             * @description Client clock (s), non-decreasing.
             */
            timestamp: number;
            /**
             * Frame Id
             * @description Echoed back.
             */
            frame_id?: string | null;
            prior?: components["schemas"]["PosePriorIn"] | null;
            /** @description The gravity direction the device measures in this frame's camera (as for localize; `convention` defaults to the session's): a factor on the frame's tilt against the map's up axis. */
            gravity?: components["schemas"]["GravityIn"] | null;
        };
        /**
         * SessionFrameOut
         * @description A frame's answer.
         */
        SessionFrameOut: {
            /** Frame Index */
            frame_index: number;
            /** Frame Id */
            frame_id: string | null;
            /** Timestamp */
            timestamp: number;
            /**
             * State
             * @description initializing, tracking or lost.
             */
            state: string;
            /**
             * Reason
             * @description Why no pose: waiting_for_constraints, ambiguous, lost, time_budget_exceeded (the frame was counted but not fused: its CPU budget or its request's ran out); with a pose: detections_unexplained (the frame's usable detections are all unexplained at the pose; confidence 0 when two or more are, lowered when one is); else None.
             */
            reason: string | null;
            world_from_camera: components["schemas"]["PoseOut"] | null;
            covariance: components["schemas"]["CovarianceOut"] | null;
            /** @description Alignment of the app's odometry frame to the map (same in both camera conventions); apply it once to the app's scene. */
            world_from_odom: components["schemas"]["PoseOut"] | null;
            /** @description 6x6 [omega, v], right perturbation, in the ODOMETRY frame's axes, given this frame's odometry pose. */
            world_from_odom_covariance: components["schemas"]["CovarianceOut"] | null;
            /**
             * Confidence
             * @description P(pose within 10 cm and 5 deg): the posterior probability of the session's place times P(within tolerance) under the pose posterior; 0 unless tracking; when detections_unexplained, 0 with two or more unexplained detections, lowered by Bayes' rule (likelihood ratio 0.1) with one.
             */
            confidence: number;
            /** Inliers */
            inliers: components["schemas"]["InlierOut"][];
            /**
             * Zone
             * @description The map zone (docs/maps.md) holding the most of this pose's inlier objects; ties: the zone with the fewest objects (a room before its floor), then the first in the map's `zones`. null when the map has no zones or none holds an inlier.
             */
            zone?: string | null;
            /**
             * Candidates
             * @description The places the walk may be in with their probabilities (>= 0.01), most probable first; several while `ambiguous`.
             */
            candidates?: components["schemas"]["PlaceCandidateOut"][];
            /** N Usable Detections */
            n_usable_detections: number;
            /** Timings Ms */
            timings_ms: {
                [key: string]: number;
            };
        };
        /**
         * SessionFramesIn
         * @description Several frames in time order (offline recording).
         */
        SessionFramesIn: {
            /** Frames */
            frames: components["schemas"]["SessionFrameIn"][];
        };
        /** SessionFramesOut */
        SessionFramesOut: {
            /** Session Id */
            session_id: string;
            /** Results */
            results: components["schemas"]["SessionFrameOut"][];
        };
        /**
         * SessionOptionsIn
         * @description Session options; omitted fields take the defaults shown.
         */
        SessionOptionsIn: {
            /**
             * Window Frames
             * @description Camera poses kept in the sliding window (at most 300 with isam2, 60 with batch).
             * @default 30
             */
            window_frames?: number;
            /**
             * Smoother
             * @description isam2 (incremental fixed-lag) or batch (LM per frame).
             * @default isam2
             */
            smoother?: string;
            /**
             * Inlier Iou
             * @default 0.2
             */
            inlier_iou?: number;
            /**
             * Odometry Translation M Per Sqrt M
             * @description Odometry random-walk translation std after 1 m travelled (m); variance grows per metre.
             * @default 0.02
             */
            odometry_translation_m_per_sqrt_m?: number;
            /**
             * Odometry Translation M Per Sqrt S
             * @description ... after 1 s (m); variance grows per second.
             * @default 0.003
             */
            odometry_translation_m_per_sqrt_s?: number;
            /**
             * Odometry Rotation Deg Per Sqrt M
             * @default 0.5
             */
            odometry_rotation_deg_per_sqrt_m?: number;
            /**
             * Odometry Rotation Deg Per Sqrt S
             * @default 0.05
             */
            odometry_rotation_deg_per_sqrt_s?: number;
        };
        /**
         * SessionOut
         * @description A session's description.
         */
        SessionOut: {
            /** Session Id */
            session_id: string;
            /**
             * Url
             * @description The session's resource path.
             */
            url: string;
            /** Map Id */
            map_id: string;
            /** Map Version */
            map_version: number;
            /**
             * Convention
             * @enum {string}
             */
            convention: "opencv" | "opengl";
            /**
             * State
             * @description initializing, tracking or lost.
             */
            state: string;
            /**
             * Frames
             * @description Frames received so far.
             */
            frames: number;
            /**
             * Idle Timeout S
             * @description The session expires after this idle time.
             */
            idle_timeout_s: number;
        };
        /**
         * SizePriorIn
         * @description Prior on every log semi-axis of a label's objects: ``N(log semi_axis_m, log_sigma^2)``.
         */
        SizePriorIn: {
            /**
             * Semi Axis M
             * @description Typical semi-axis (m).
             */
            semi_axis_m: number;
            /**
             * Log Sigma
             * @description Std of the log semi-axis (dimensionless).
             * @default 0.5
             */
            log_sigma?: number;
        };
    };
    responses: never;
    parameters: never;
    requestBodies: never;
    headers: never;
    pathItems: never;
}
export type $defs = Record<string, never>;
export interface operations {
    localize_frame_v1_maps__map_id__localize_post: {
        parameters: {
            query?: {
                /** @description Map version (default: latest). */
                version?: number | null;
            };
            header?: {
                /** @description `image/svg+xml` for the frame drawn (see above) */
                accept?: string | null;
            };
            path: {
                /** @description Map id (pattern: quadloc.maps.model.MAP_ID_PATTERN). */
                map_id: string;
            };
            cookie?: never;
        };
        requestBody: {
            content: {
                "application/json": components["schemas"]["LocalizeRequest"];
            };
        };
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "localized": true,
                     *       "world_from_camera": {
                     *         "quaternion_wxyz": [
                     *           0.4548445178539943,
                     *           -0.8873214761952826,
                     *           -0.07486678892946097,
                     *           0.013115882592625852
                     *         ],
                     *         "quaternion_xyzw": [
                     *           -0.8873214761952826,
                     *           -0.07486678892946097,
                     *           0.013115882592625852,
                     *           0.4548445178539943
                     *         ],
                     *         "translation_m": [
                     *           -0.026321555098973083,
                     *           -0.3047978874404054,
                     *           0.776237648667705
                     *         ],
                     *         "matrix": [
                     *           [
                     *             0.9884458750784157,
                     *             0.12093044475363489,
                     *             -0.09138150563518047,
                     *             -0.026321555098973083
                     *           ],
                     *           [
                     *             0.1447931939299249,
                     *             -0.5750228569871179,
                     *             0.8052227300157043,
                     *             -0.3047978874404054
                     *           ],
                     *           [
                     *             0.04482948842040934,
                     *             -0.8091505060704469,
                     *             -0.5858888764039677,
                     *             0.776237648667705
                     *           ],
                     *           [
                     *             0,
                     *             0,
                     *             0,
                     *             1
                     *           ]
                     *         ],
                     *         "matrix_column_major": [
                     *           0.9884458750784157,
                     *           0.1447931939299249,
                     *           0.04482948842040934,
                     *           0,
                     *           0.12093044475363489,
                     *           -0.5750228569871179,
                     *           -0.8091505060704469,
                     *           0,
                     *           -0.09138150563518047,
                     *           0.8052227300157043,
                     *           -0.5858888764039677,
                     *           0,
                     *           -0.026321555098973083,
                     *           -0.3047978874404054,
                     *           0.776237648667705,
                     *           1
                     *         ],
                     *         "convention": "opencv"
                     *       },
                     *       "covariance": {
                     *         "order": [
                     *           "omega_x",
                     *           "omega_y",
                     *           "omega_z",
                     *           "v_x",
                     *           "v_y",
                     *           "v_z"
                     *         ],
                     *         "frame": "camera (body) frame, right perturbation T*exp(xi), omega in rad, v in m",
                     *         "matrix": [
                     *           [
                     *             0.000016977568509757757,
                     *             -0.0000063671493243252185,
                     *             0.0000022356674489009446,
                     *             0.00001620521855668606,
                     *             0.00003699291229840474,
                     *             0.000008611498596778098
                     *           ],
                     *           [
                     *             -0.0000063671493243252185,
                     *             0.000014693907639038927,
                     *             -0.0000029759977885987955,
                     *             -0.00003416205376089812,
                     *             -0.00001306199566000215,
                     *             0.000001604671054453153
                     *           ],
                     *           [
                     *             0.0000022356674489009446,
                     *             -0.0000029759977885987955,
                     *             0.000005322064359205505,
                     *             0.000004916146011765421,
                     *             0.0000028659609246244567,
                     *             -8.947761166819572e-7
                     *           ],
                     *           [
                     *             0.00001620521855668606,
                     *             -0.00003416205376089812,
                     *             0.000004916146011765421,
                     *             0.00008470729345196574,
                     *             0.00003290782429876545,
                     *             0.00000545187870673539
                     *           ],
                     *           [
                     *             0.00003699291229840474,
                     *             -0.00001306199566000215,
                     *             0.0000028659609246244567,
                     *             0.00003290782429876545,
                     *             0.00008403000171557075,
                     *             0.0000152925144027545
                     *           ],
                     *           [
                     *             0.000008611498596778098,
                     *             0.000001604671054453153,
                     *             -8.947761166819572e-7,
                     *             0.00000545187870673539,
                     *             0.0000152925144027545,
                     *             0.000032685911137201335
                     *           ]
                     *         ]
                     *       },
                     *       "confidence": 0.9987997893796008,
                     *       "inliers": [
                     *         {
                     *           "detection_index": 0,
                     *           "object_id": "9",
                     *           "iou": 0.45962622638050254,
                     *           "cost": 25.72050323320806
                     *         },
                     *         {
                     *           "detection_index": 1,
                     *           "object_id": "4",
                     *           "iou": 0.9530198384273678,
                     *           "cost": 0.3651805955130491
                     *         },
                     *         {
                     *           "detection_index": 2,
                     *           "object_id": "6",
                     *           "iou": 0.9746926163458942,
                     *           "cost": 0.10861710876655467
                     *         },
                     *         {
                     *           "detection_index": 3,
                     *           "object_id": "10",
                     *           "iou": 0.4821206397109295,
                     *           "cost": 25.529437586104436
                     *         },
                     *         {
                     *           "detection_index": 4,
                     *           "object_id": "2",
                     *           "iou": 0.9364145252063931,
                     *           "cost": 0.6417867695923196
                     *         },
                     *         {
                     *           "detection_index": 5,
                     *           "object_id": "3",
                     *           "iou": 0.8565113023409483,
                     *           "cost": 3.3748415901720206
                     *         },
                     *         {
                     *           "detection_index": 6,
                     *           "object_id": "8",
                     *           "iou": 0.9698068292328067,
                     *           "cost": 0.11450283808425779
                     *         },
                     *         {
                     *           "detection_index": 7,
                     *           "object_id": "5",
                     *           "iou": 0.9121055930480997,
                     *           "cost": 1.2065262797496068
                     *         },
                     *         {
                     *           "detection_index": 8,
                     *           "object_id": "7",
                     *           "iou": 0.9061096277348163,
                     *           "cost": 1.4425100156241584
                     *         }
                     *       ],
                     *       "metric": "level_set",
                     *       "hypotheses_evaluated": 53,
                     *       "used_prior": false,
                     *       "refinement_status": "converged",
                     *       "pose_source": "ransac",
                     *       "alternatives": [],
                     *       "map_id": "chess",
                     *       "map_version": 1,
                     *       "timings_ms": {
                     *         "validate": 0.02,
                     *         "hypotheses": 16.7,
                     *         "refine": 3.12,
                     *         "total": 20.39
                     *       },
                     *       "frame_id": "seq-03/frame-000022",
                     *       "timestamp": 1700000001.3333333
                     *     }
                     */
                    "application/json": components["schemas"]["LocalizeResponse"];
                    "image/svg+xml": string;
                };
            };
            /** @description Malformed or unreadable body */
            400: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:malformed-json",
                     *       "title": "Malformed JSON body",
                     *       "status": 400,
                     *       "detail": "Malformed JSON body",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Request body too large */
            413: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:payload-too-large",
                     *       "title": "Request body too large",
                     *       "status": 413,
                     *       "detail": "Request body too large",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Unsupported media type */
            415: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unsupported-media-type",
                     *       "title": "Unsupported media type",
                     *       "status": 415,
                     *       "detail": "Unsupported media type",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    localize_batch_v1_maps__map_id__localize_batch_post: {
        parameters: {
            query?: {
                /** @description Map version (default: latest). */
                version?: number | null;
            };
            header?: never;
            path: {
                /** @description Map id (pattern: quadloc.maps.model.MAP_ID_PATTERN). */
                map_id: string;
            };
            cookie?: never;
        };
        requestBody: {
            content: {
                "application/json": components["schemas"]["BatchLocalizeRequest"];
            };
        };
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "map_id": "chess",
                     *       "map_version": 1,
                     *       "results": [
                     *         {
                     *           "localized": true,
                     *           "world_from_camera": {
                     *             "quaternion_wxyz": [
                     *               0.4548445178539943,
                     *               -0.8873214761952826,
                     *               -0.07486678892946097,
                     *               0.013115882592625852
                     *             ],
                     *             "quaternion_xyzw": [
                     *               -0.8873214761952826,
                     *               -0.07486678892946097,
                     *               0.013115882592625852,
                     *               0.4548445178539943
                     *             ],
                     *             "translation_m": [
                     *               -0.026321555098973083,
                     *               -0.3047978874404054,
                     *               0.776237648667705
                     *             ],
                     *             "matrix": [
                     *               [
                     *                 0.9884458750784157,
                     *                 0.12093044475363489,
                     *                 -0.09138150563518047,
                     *                 -0.026321555098973083
                     *               ],
                     *               [
                     *                 0.1447931939299249,
                     *                 -0.5750228569871179,
                     *                 0.8052227300157043,
                     *                 -0.3047978874404054
                     *               ],
                     *               [
                     *                 0.04482948842040934,
                     *                 -0.8091505060704469,
                     *                 -0.5858888764039677,
                     *                 0.776237648667705
                     *               ],
                     *               [
                     *                 0,
                     *                 0,
                     *                 0,
                     *                 1
                     *               ]
                     *             ],
                     *             "matrix_column_major": [
                     *               0.9884458750784157,
                     *               0.1447931939299249,
                     *               0.04482948842040934,
                     *               0,
                     *               0.12093044475363489,
                     *               -0.5750228569871179,
                     *               -0.8091505060704469,
                     *               0,
                     *               -0.09138150563518047,
                     *               0.8052227300157043,
                     *               -0.5858888764039677,
                     *               0,
                     *               -0.026321555098973083,
                     *               -0.3047978874404054,
                     *               0.776237648667705,
                     *               1
                     *             ],
                     *             "convention": "opencv"
                     *           },
                     *           "covariance": {
                     *             "order": [
                     *               "omega_x",
                     *               "omega_y",
                     *               "omega_z",
                     *               "v_x",
                     *               "v_y",
                     *               "v_z"
                     *             ],
                     *             "frame": "camera (body) frame, right perturbation T*exp(xi), omega in rad, v in m",
                     *             "matrix": [
                     *               [
                     *                 0.000016977568509757757,
                     *                 -0.0000063671493243252185,
                     *                 0.0000022356674489009446,
                     *                 0.00001620521855668606,
                     *                 0.00003699291229840474,
                     *                 0.000008611498596778098
                     *               ],
                     *               [
                     *                 -0.0000063671493243252185,
                     *                 0.000014693907639038927,
                     *                 -0.0000029759977885987955,
                     *                 -0.00003416205376089812,
                     *                 -0.00001306199566000215,
                     *                 0.000001604671054453153
                     *               ],
                     *               [
                     *                 0.0000022356674489009446,
                     *                 -0.0000029759977885987955,
                     *                 0.000005322064359205505,
                     *                 0.000004916146011765421,
                     *                 0.0000028659609246244567,
                     *                 -8.947761166819572e-7
                     *               ],
                     *               [
                     *                 0.00001620521855668606,
                     *                 -0.00003416205376089812,
                     *                 0.000004916146011765421,
                     *                 0.00008470729345196574,
                     *                 0.00003290782429876545,
                     *                 0.00000545187870673539
                     *               ],
                     *               [
                     *                 0.00003699291229840474,
                     *                 -0.00001306199566000215,
                     *                 0.0000028659609246244567,
                     *                 0.00003290782429876545,
                     *                 0.00008403000171557075,
                     *                 0.0000152925144027545
                     *               ],
                     *               [
                     *                 0.000008611498596778098,
                     *                 0.000001604671054453153,
                     *                 -8.947761166819572e-7,
                     *                 0.00000545187870673539,
                     *                 0.0000152925144027545,
                     *                 0.000032685911137201335
                     *               ]
                     *             ]
                     *           },
                     *           "confidence": 0.9987997893796008,
                     *           "inliers": [
                     *             {
                     *               "detection_index": 0,
                     *               "object_id": "9",
                     *               "iou": 0.45962622638050254,
                     *               "cost": 25.72050323320806
                     *             },
                     *             {
                     *               "detection_index": 1,
                     *               "object_id": "4",
                     *               "iou": 0.9530198384273678,
                     *               "cost": 0.3651805955130491
                     *             },
                     *             {
                     *               "detection_index": 2,
                     *               "object_id": "6",
                     *               "iou": 0.9746926163458942,
                     *               "cost": 0.10861710876655467
                     *             },
                     *             {
                     *               "detection_index": 3,
                     *               "object_id": "10",
                     *               "iou": 0.4821206397109295,
                     *               "cost": 25.529437586104436
                     *             },
                     *             {
                     *               "detection_index": 4,
                     *               "object_id": "2",
                     *               "iou": 0.9364145252063931,
                     *               "cost": 0.6417867695923196
                     *             },
                     *             {
                     *               "detection_index": 5,
                     *               "object_id": "3",
                     *               "iou": 0.8565113023409483,
                     *               "cost": 3.3748415901720206
                     *             },
                     *             {
                     *               "detection_index": 6,
                     *               "object_id": "8",
                     *               "iou": 0.9698068292328067,
                     *               "cost": 0.11450283808425779
                     *             },
                     *             {
                     *               "detection_index": 7,
                     *               "object_id": "5",
                     *               "iou": 0.9121055930480997,
                     *               "cost": 1.2065262797496068
                     *             },
                     *             {
                     *               "detection_index": 8,
                     *               "object_id": "7",
                     *               "iou": 0.9061096277348163,
                     *               "cost": 1.4425100156241584
                     *             }
                     *           ],
                     *           "metric": "level_set",
                     *           "hypotheses_evaluated": 53,
                     *           "used_prior": false,
                     *           "refinement_status": "converged",
                     *           "pose_source": "ransac",
                     *           "alternatives": [],
                     *           "map_id": "chess",
                     *           "map_version": 1,
                     *           "timings_ms": {
                     *             "validate": 0.02,
                     *             "hypotheses": 16.7,
                     *             "refine": 3.12,
                     *             "total": 20.39
                     *           },
                     *           "frame_id": "seq-03/frame-000022",
                     *           "timestamp": 1700000001.3333333
                     *         },
                     *         {
                     *           "localized": true,
                     *           "world_from_camera": {
                     *             "quaternion_wxyz": [
                     *               0.4548445178539943,
                     *               -0.8873214761952826,
                     *               -0.07486678892946097,
                     *               0.013115882592625852
                     *             ],
                     *             "quaternion_xyzw": [
                     *               -0.8873214761952826,
                     *               -0.07486678892946097,
                     *               0.013115882592625852,
                     *               0.4548445178539943
                     *             ],
                     *             "translation_m": [
                     *               -0.026321555098973083,
                     *               -0.3047978874404054,
                     *               0.776237648667705
                     *             ],
                     *             "matrix": [
                     *               [
                     *                 0.9884458750784157,
                     *                 0.12093044475363489,
                     *                 -0.09138150563518047,
                     *                 -0.026321555098973083
                     *               ],
                     *               [
                     *                 0.1447931939299249,
                     *                 -0.5750228569871179,
                     *                 0.8052227300157043,
                     *                 -0.3047978874404054
                     *               ],
                     *               [
                     *                 0.04482948842040934,
                     *                 -0.8091505060704469,
                     *                 -0.5858888764039677,
                     *                 0.776237648667705
                     *               ],
                     *               [
                     *                 0,
                     *                 0,
                     *                 0,
                     *                 1
                     *               ]
                     *             ],
                     *             "matrix_column_major": [
                     *               0.9884458750784157,
                     *               0.1447931939299249,
                     *               0.04482948842040934,
                     *               0,
                     *               0.12093044475363489,
                     *               -0.5750228569871179,
                     *               -0.8091505060704469,
                     *               0,
                     *               -0.09138150563518047,
                     *               0.8052227300157043,
                     *               -0.5858888764039677,
                     *               0,
                     *               -0.026321555098973083,
                     *               -0.3047978874404054,
                     *               0.776237648667705,
                     *               1
                     *             ],
                     *             "convention": "opencv"
                     *           },
                     *           "covariance": {
                     *             "order": [
                     *               "omega_x",
                     *               "omega_y",
                     *               "omega_z",
                     *               "v_x",
                     *               "v_y",
                     *               "v_z"
                     *             ],
                     *             "frame": "camera (body) frame, right perturbation T*exp(xi), omega in rad, v in m",
                     *             "matrix": [
                     *               [
                     *                 0.000016977568509757757,
                     *                 -0.0000063671493243252185,
                     *                 0.0000022356674489009446,
                     *                 0.00001620521855668606,
                     *                 0.00003699291229840474,
                     *                 0.000008611498596778098
                     *               ],
                     *               [
                     *                 -0.0000063671493243252185,
                     *                 0.000014693907639038927,
                     *                 -0.0000029759977885987955,
                     *                 -0.00003416205376089812,
                     *                 -0.00001306199566000215,
                     *                 0.000001604671054453153
                     *               ],
                     *               [
                     *                 0.0000022356674489009446,
                     *                 -0.0000029759977885987955,
                     *                 0.000005322064359205505,
                     *                 0.000004916146011765421,
                     *                 0.0000028659609246244567,
                     *                 -8.947761166819572e-7
                     *               ],
                     *               [
                     *                 0.00001620521855668606,
                     *                 -0.00003416205376089812,
                     *                 0.000004916146011765421,
                     *                 0.00008470729345196574,
                     *                 0.00003290782429876545,
                     *                 0.00000545187870673539
                     *               ],
                     *               [
                     *                 0.00003699291229840474,
                     *                 -0.00001306199566000215,
                     *                 0.0000028659609246244567,
                     *                 0.00003290782429876545,
                     *                 0.00008403000171557075,
                     *                 0.0000152925144027545
                     *               ],
                     *               [
                     *                 0.000008611498596778098,
                     *                 0.000001604671054453153,
                     *                 -8.947761166819572e-7,
                     *                 0.00000545187870673539,
                     *                 0.0000152925144027545,
                     *                 0.000032685911137201335
                     *               ]
                     *             ]
                     *           },
                     *           "confidence": 0.9987997893796008,
                     *           "inliers": [
                     *             {
                     *               "detection_index": 0,
                     *               "object_id": "9",
                     *               "iou": 0.45962622638050254,
                     *               "cost": 25.72050323320806
                     *             },
                     *             {
                     *               "detection_index": 1,
                     *               "object_id": "4",
                     *               "iou": 0.9530198384273678,
                     *               "cost": 0.3651805955130491
                     *             },
                     *             {
                     *               "detection_index": 2,
                     *               "object_id": "6",
                     *               "iou": 0.9746926163458942,
                     *               "cost": 0.10861710876655467
                     *             },
                     *             {
                     *               "detection_index": 3,
                     *               "object_id": "10",
                     *               "iou": 0.4821206397109295,
                     *               "cost": 25.529437586104436
                     *             },
                     *             {
                     *               "detection_index": 4,
                     *               "object_id": "2",
                     *               "iou": 0.9364145252063931,
                     *               "cost": 0.6417867695923196
                     *             },
                     *             {
                     *               "detection_index": 5,
                     *               "object_id": "3",
                     *               "iou": 0.8565113023409483,
                     *               "cost": 3.3748415901720206
                     *             },
                     *             {
                     *               "detection_index": 6,
                     *               "object_id": "8",
                     *               "iou": 0.9698068292328067,
                     *               "cost": 0.11450283808425779
                     *             },
                     *             {
                     *               "detection_index": 7,
                     *               "object_id": "5",
                     *               "iou": 0.9121055930480997,
                     *               "cost": 1.2065262797496068
                     *             },
                     *             {
                     *               "detection_index": 8,
                     *               "object_id": "7",
                     *               "iou": 0.9061096277348163,
                     *               "cost": 1.4425100156241584
                     *             }
                     *           ],
                     *           "metric": "level_set",
                     *           "hypotheses_evaluated": 53,
                     *           "used_prior": false,
                     *           "refinement_status": "converged",
                     *           "pose_source": "ransac",
                     *           "alternatives": [],
                     *           "map_id": "chess",
                     *           "map_version": 1,
                     *           "timings_ms": {
                     *             "validate": 0.02,
                     *             "hypotheses": 16.7,
                     *             "refine": 3.12,
                     *             "total": 20.39
                     *           },
                     *           "frame_id": "seq-03/frame-000022",
                     *           "timestamp": 1700000001.3333333
                     *         }
                     *       ]
                     *     }
                     */
                    "application/json": components["schemas"]["BatchLocalizeResponse"];
                };
            };
            /** @description Malformed or unreadable body */
            400: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:malformed-json",
                     *       "title": "Malformed JSON body",
                     *       "status": 400,
                     *       "detail": "Malformed JSON body",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Request body too large */
            413: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:payload-too-large",
                     *       "title": "Request body too large",
                     *       "status": 413,
                     *       "detail": "Request body too large",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Unsupported media type */
            415: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unsupported-media-type",
                     *       "title": "Unsupported media type",
                     *       "status": 415,
                     *       "detail": "Unsupported media type",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    list_maps_v1_maps_get: {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "maps": [
                     *         {
                     *           "map_id": "office-3",
                     *           "name": "Office, third floor",
                     *           "version": 1,
                     *           "content_hash": "1feb9616bdac959eeff6727ad640bc19e0e577f3e7c8309b8a15ac0fbde0578c",
                     *           "updated_at": "2026-01-05T10:00:00+00:00"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/json": components["schemas"]["MapListOut"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    create_map_v1_maps_post: {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        requestBody: {
            content: {
                /**
                 * @example {
                 *       "format": "quadloc.map/1",
                 *       "map_id": "office-3",
                 *       "name": "Office, third floor",
                 *       "up_axis": [
                 *         0,
                 *         0,
                 *         1
                 *       ],
                 *       "categories": [
                 *         "chair",
                 *         "monitor",
                 *         "plant"
                 *       ],
                 *       "objects": [
                 *         {
                 *           "object_id": "chair-1",
                 *           "category": "chair",
                 *           "center": [
                 *             1.2,
                 *             0.4,
                 *             0.45
                 *           ],
                 *           "axes": [
                 *             0.3,
                 *             0.3,
                 *             0.45
                 *           ],
                 *           "quaternion_wxyz": [
                 *             1,
                 *             0,
                 *             0,
                 *             0
                 *           ]
                 *         },
                 *         {
                 *           "object_id": "monitor-1",
                 *           "category": "monitor",
                 *           "center": [
                 *             1.5,
                 *             1.1,
                 *             0.95
                 *           ],
                 *           "axes": [
                 *             0.3,
                 *             0.05,
                 *             0.2
                 *           ],
                 *           "quaternion_wxyz": [
                 *             0.9238795,
                 *             0,
                 *             0,
                 *             0.3826834
                 *           ]
                 *         },
                 *         {
                 *           "object_id": "plant-1",
                 *           "category": "plant",
                 *           "center": [
                 *             -0.4,
                 *             2,
                 *             0.6
                 *           ],
                 *           "axes": [
                 *             0.25,
                 *             0.25,
                 *             0.6
                 *           ]
                 *         }
                 *       ],
                 *       "metadata": {
                 *         "source": "example"
                 *       }
                 *     }
                 */
                "application/json": {
                    /**
                     * @default quadloc.map/1
                     * @constant
                     */
                    format?: "quadloc.map/1";
                    map_id: string;
                    name: string;
                    /**
                     * @description Set by the store; ignored on create/update.
                     * @default 1
                     */
                    version?: number;
                    /**
                     * @description World up direction (default [0, 0, 1]).
                     * @default [
                     *       0,
                     *       0,
                     *       1
                     *     ]
                     */
                    up_axis?: number[];
                    categories: string[];
                    objects: {
                        object_id: string;
                        category: string;
                        /** @description World metres. */
                        center: number[];
                        /** @description Semi-axes in metres. */
                        axes: number[];
                        /** @description Unit quaternion (w, x, y, z), ellipsoid frame -> world. */
                        quaternion_wxyz?: number[];
                        /** @description 3x3 rotation, ellipsoid frame -> world (alternative to quaternion_wxyz). */
                        rotation?: number[][];
                    }[];
                    /** @default {} */
                    metadata?: {
                        [key: string]: unknown;
                    };
                    /**
                     * @description Optional named groups of objects (rooms, floors); answers name the zone of their pose (docs/maps.md).
                     * @default []
                     */
                    zones?: {
                        zone_id: string;
                        object_ids: string[];
                        name?: string;
                        parent?: string;
                    }[];
                };
            };
        };
        responses: {
            /** @description Successful Response */
            201: {
                headers: {
                    /** @description Strong ETag: the version's content hash. */
                    ETag?: string;
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "map_id": "office-3",
                     *       "version": 1,
                     *       "content_hash": "1feb9616bdac959eeff6727ad640bc19e0e577f3e7c8309b8a15ac0fbde0578c",
                     *       "created_at": "2026-01-05T10:00:00+00:00",
                     *       "map": {
                     *         "format": "quadloc.map/1",
                     *         "map_id": "office-3",
                     *         "name": "Office, third floor",
                     *         "version": 1,
                     *         "up_axis": [
                     *           0,
                     *           0,
                     *           1
                     *         ],
                     *         "categories": [
                     *           "chair",
                     *           "monitor",
                     *           "plant"
                     *         ],
                     *         "objects": [
                     *           {
                     *             "object_id": "chair-1",
                     *             "category": "chair",
                     *             "center": [
                     *               1.2,
                     *               0.4,
                     *               0.45
                     *             ],
                     *             "axes": [
                     *               0.3,
                     *               0.3,
                     *               0.45
                     *             ],
                     *             "quaternion_wxyz": [
                     *               1,
                     *               0,
                     *               0,
                     *               0
                     *             ]
                     *           },
                     *           {
                     *             "object_id": "monitor-1",
                     *             "category": "monitor",
                     *             "center": [
                     *               1.5,
                     *               1.1,
                     *               0.95
                     *             ],
                     *             "axes": [
                     *               0.3,
                     *               0.05,
                     *               0.2
                     *             ],
                     *             "quaternion_wxyz": [
                     *               0.9238795391929064,
                     *               0,
                     *               0,
                     *               0.38268341623423263
                     *             ]
                     *           },
                     *           {
                     *             "object_id": "plant-1",
                     *             "category": "plant",
                     *             "center": [
                     *               -0.4,
                     *               2,
                     *               0.6
                     *             ],
                     *             "axes": [
                     *               0.25,
                     *               0.25,
                     *               0.6
                     *             ],
                     *             "quaternion_wxyz": [
                     *               1,
                     *               0,
                     *               0,
                     *               0
                     *             ]
                     *           }
                     *         ],
                     *         "metadata": {
                     *           "source": "example"
                     *         }
                     *       }
                     *     }
                     */
                    "application/json": components["schemas"]["MapOut"];
                };
            };
            /** @description Malformed or unreadable body */
            400: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:malformed-json",
                     *       "title": "Malformed JSON body",
                     *       "status": 400,
                     *       "detail": "Malformed JSON body",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Conflict: map id taken, or an update lost a race */
            409: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:version-conflict",
                     *       "title": "Map version conflict",
                     *       "status": 409,
                     *       "detail": "Map version conflict",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Request body too large */
            413: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:payload-too-large",
                     *       "title": "Request body too large",
                     *       "status": 413,
                     *       "detail": "Request body too large",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Unsupported media type */
            415: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unsupported-media-type",
                     *       "title": "Unsupported media type",
                     *       "status": 415,
                     *       "detail": "Unsupported media type",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    import_chess_map_v1_maps_import_chess_post: {
        parameters: {
            query: {
                /** @description Id of the new map. */
                map_id: string;
                name?: string;
            };
            header?: never;
            path?: never;
            cookie?: never;
        };
        requestBody: {
            content: {
                /**
                 * @example {
                 *       "category_id_to_label": {
                 *         "0": "TV",
                 *         "2": "Chair"
                 *       },
                 *       "objects": [
                 *         {
                 *           "category_id": 0,
                 *           "object_id": 0,
                 *           "ellipsoid": {
                 *             "axes": [
                 *               0.17790342378298427,
                 *               0.4196947342281149,
                 *               0.34077547801835967
                 *             ],
                 *             "R": [
                 *               [
                 *                 0.6265048551007313,
                 *                 -0.720591209564343,
                 *                 0.2970521422811295
                 *               ],
                 *               [
                 *                 -0.712602874538981,
                 *                 -0.6839553939233161,
                 *                 -0.1562119147887997
                 *               ],
                 *               [
                 *                 0.31573534761567823,
                 *                 -0.11381268743773053,
                 *                 -0.9419967422683628
                 *               ]
                 *             ],
                 *             "center": [
                 *               -0.6475552230828737,
                 *               1.6728880646773112,
                 *               0.458813457746605
                 *             ]
                 *           }
                 *         },
                 *         {
                 *           "category_id": 2,
                 *           "object_id": 1,
                 *           "ellipsoid": {
                 *             "axes": [
                 *               0.3,
                 *               0.3,
                 *               0.45
                 *             ],
                 *             "R": [
                 *               [
                 *                 1,
                 *                 0,
                 *                 0
                 *               ],
                 *               [
                 *                 0,
                 *                 1,
                 *                 0
                 *               ],
                 *               [
                 *                 0,
                 *                 0,
                 *                 1
                 *               ]
                 *             ],
                 *             "center": [
                 *               0.5,
                 *               1,
                 *               0.45
                 *             ]
                 *           }
                 *         }
                 *       ]
                 *     }
                 */
                "application/json": {
                    category_id_to_label: {
                        [key: string]: string;
                    };
                    objects: {
                        category_id: number | string;
                        object_id: number | string;
                        ellipsoid: {
                            /** @description Semi-axes in metres. */
                            axes: number[];
                            /** @description 3x3 rotation, ellipsoid frame -> world (alternative to quaternion_wxyz). */
                            R: number[][];
                            /** @description World metres. */
                            center: number[];
                        };
                    }[];
                };
            };
        };
        responses: {
            /** @description Successful Response */
            201: {
                headers: {
                    /** @description Strong ETag: the version's content hash. */
                    ETag?: string;
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "map_id": "office-3",
                     *       "version": 1,
                     *       "content_hash": "1feb9616bdac959eeff6727ad640bc19e0e577f3e7c8309b8a15ac0fbde0578c",
                     *       "created_at": "2026-01-05T10:00:00+00:00",
                     *       "map": {
                     *         "format": "quadloc.map/1",
                     *         "map_id": "office-3",
                     *         "name": "Office, third floor",
                     *         "version": 1,
                     *         "up_axis": [
                     *           0,
                     *           0,
                     *           1
                     *         ],
                     *         "categories": [
                     *           "chair",
                     *           "monitor",
                     *           "plant"
                     *         ],
                     *         "objects": [
                     *           {
                     *             "object_id": "chair-1",
                     *             "category": "chair",
                     *             "center": [
                     *               1.2,
                     *               0.4,
                     *               0.45
                     *             ],
                     *             "axes": [
                     *               0.3,
                     *               0.3,
                     *               0.45
                     *             ],
                     *             "quaternion_wxyz": [
                     *               1,
                     *               0,
                     *               0,
                     *               0
                     *             ]
                     *           },
                     *           {
                     *             "object_id": "monitor-1",
                     *             "category": "monitor",
                     *             "center": [
                     *               1.5,
                     *               1.1,
                     *               0.95
                     *             ],
                     *             "axes": [
                     *               0.3,
                     *               0.05,
                     *               0.2
                     *             ],
                     *             "quaternion_wxyz": [
                     *               0.9238795391929064,
                     *               0,
                     *               0,
                     *               0.38268341623423263
                     *             ]
                     *           },
                     *           {
                     *             "object_id": "plant-1",
                     *             "category": "plant",
                     *             "center": [
                     *               -0.4,
                     *               2,
                     *               0.6
                     *             ],
                     *             "axes": [
                     *               0.25,
                     *               0.25,
                     *               0.6
                     *             ],
                     *             "quaternion_wxyz": [
                     *               1,
                     *               0,
                     *               0,
                     *               0
                     *             ]
                     *           }
                     *         ],
                     *         "metadata": {
                     *           "source": "example"
                     *         }
                     *       }
                     *     }
                     */
                    "application/json": components["schemas"]["MapOut"];
                };
            };
            /** @description Malformed or unreadable body */
            400: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:malformed-json",
                     *       "title": "Malformed JSON body",
                     *       "status": 400,
                     *       "detail": "Malformed JSON body",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Conflict: map id taken, or an update lost a race */
            409: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:version-conflict",
                     *       "title": "Map version conflict",
                     *       "status": 409,
                     *       "detail": "Map version conflict",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Request body too large */
            413: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:payload-too-large",
                     *       "title": "Request body too large",
                     *       "status": 413,
                     *       "detail": "Request body too large",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Unsupported media type */
            415: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unsupported-media-type",
                     *       "title": "Unsupported media type",
                     *       "status": 415,
                     *       "detail": "Unsupported media type",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    get_map_v1_maps__map_id__get: {
        parameters: {
            query?: {
                version?: number | null;
            };
            header?: never;
            path: {
                /** @description Map id (pattern: quadloc.maps.model.MAP_ID_PATTERN). */
                map_id: string;
            };
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    /** @description Strong ETag: the version's content hash. */
                    ETag?: string;
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "map_id": "office-3",
                     *       "version": 1,
                     *       "content_hash": "1feb9616bdac959eeff6727ad640bc19e0e577f3e7c8309b8a15ac0fbde0578c",
                     *       "created_at": "2026-01-05T10:00:00+00:00",
                     *       "map": {
                     *         "format": "quadloc.map/1",
                     *         "map_id": "office-3",
                     *         "name": "Office, third floor",
                     *         "version": 1,
                     *         "up_axis": [
                     *           0,
                     *           0,
                     *           1
                     *         ],
                     *         "categories": [
                     *           "chair",
                     *           "monitor",
                     *           "plant"
                     *         ],
                     *         "objects": [
                     *           {
                     *             "object_id": "chair-1",
                     *             "category": "chair",
                     *             "center": [
                     *               1.2,
                     *               0.4,
                     *               0.45
                     *             ],
                     *             "axes": [
                     *               0.3,
                     *               0.3,
                     *               0.45
                     *             ],
                     *             "quaternion_wxyz": [
                     *               1,
                     *               0,
                     *               0,
                     *               0
                     *             ]
                     *           },
                     *           {
                     *             "object_id": "monitor-1",
                     *             "category": "monitor",
                     *             "center": [
                     *               1.5,
                     *               1.1,
                     *               0.95
                     *             ],
                     *             "axes": [
                     *               0.3,
                     *               0.05,
                     *               0.2
                     *             ],
                     *             "quaternion_wxyz": [
                     *               0.9238795391929064,
                     *               0,
                     *               0,
                     *               0.38268341623423263
                     *             ]
                     *           },
                     *           {
                     *             "object_id": "plant-1",
                     *             "category": "plant",
                     *             "center": [
                     *               -0.4,
                     *               2,
                     *               0.6
                     *             ],
                     *             "axes": [
                     *               0.25,
                     *               0.25,
                     *               0.6
                     *             ],
                     *             "quaternion_wxyz": [
                     *               1,
                     *               0,
                     *               0,
                     *               0
                     *             ]
                     *           }
                     *         ],
                     *         "metadata": {
                     *           "source": "example"
                     *         }
                     *       }
                     *     }
                     */
                    "application/json": components["schemas"]["MapOut"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    update_map_v1_maps__map_id__put: {
        parameters: {
            query?: never;
            header: {
                /**
                 * @description ETag of the version edited (strong, as returned by GET).
                 * @example "d79f785a18e6e97f..."
                 */
                "If-Match": string;
            };
            path: {
                /** @description Map id (pattern: quadloc.maps.model.MAP_ID_PATTERN). */
                map_id: string;
            };
            cookie?: never;
        };
        requestBody: {
            content: {
                /**
                 * @example {
                 *       "format": "quadloc.map/1",
                 *       "map_id": "office-3",
                 *       "name": "Office, third floor",
                 *       "up_axis": [
                 *         0,
                 *         0,
                 *         1
                 *       ],
                 *       "categories": [
                 *         "chair",
                 *         "monitor",
                 *         "plant"
                 *       ],
                 *       "objects": [
                 *         {
                 *           "object_id": "chair-1",
                 *           "category": "chair",
                 *           "center": [
                 *             1.2,
                 *             0.4,
                 *             0.45
                 *           ],
                 *           "axes": [
                 *             0.3,
                 *             0.3,
                 *             0.45
                 *           ],
                 *           "quaternion_wxyz": [
                 *             1,
                 *             0,
                 *             0,
                 *             0
                 *           ]
                 *         },
                 *         {
                 *           "object_id": "monitor-1",
                 *           "category": "monitor",
                 *           "center": [
                 *             1.5,
                 *             1.1,
                 *             0.95
                 *           ],
                 *           "axes": [
                 *             0.3,
                 *             0.05,
                 *             0.2
                 *           ],
                 *           "quaternion_wxyz": [
                 *             0.9238795,
                 *             0,
                 *             0,
                 *             0.3826834
                 *           ]
                 *         },
                 *         {
                 *           "object_id": "plant-1",
                 *           "category": "plant",
                 *           "center": [
                 *             -0.4,
                 *             2,
                 *             0.6
                 *           ],
                 *           "axes": [
                 *             0.25,
                 *             0.25,
                 *             0.6
                 *           ]
                 *         }
                 *       ],
                 *       "metadata": {
                 *         "source": "example"
                 *       }
                 *     }
                 */
                "application/json": {
                    /**
                     * @default quadloc.map/1
                     * @constant
                     */
                    format?: "quadloc.map/1";
                    map_id: string;
                    name: string;
                    /**
                     * @description Set by the store; ignored on create/update.
                     * @default 1
                     */
                    version?: number;
                    /**
                     * @description World up direction (default [0, 0, 1]).
                     * @default [
                     *       0,
                     *       0,
                     *       1
                     *     ]
                     */
                    up_axis?: number[];
                    categories: string[];
                    objects: {
                        object_id: string;
                        category: string;
                        /** @description World metres. */
                        center: number[];
                        /** @description Semi-axes in metres. */
                        axes: number[];
                        /** @description Unit quaternion (w, x, y, z), ellipsoid frame -> world. */
                        quaternion_wxyz?: number[];
                        /** @description 3x3 rotation, ellipsoid frame -> world (alternative to quaternion_wxyz). */
                        rotation?: number[][];
                    }[];
                    /** @default {} */
                    metadata?: {
                        [key: string]: unknown;
                    };
                    /**
                     * @description Optional named groups of objects (rooms, floors); answers name the zone of their pose (docs/maps.md).
                     * @default []
                     */
                    zones?: {
                        zone_id: string;
                        object_ids: string[];
                        name?: string;
                        parent?: string;
                    }[];
                };
            };
        };
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    /** @description Strong ETag: the version's content hash. */
                    ETag?: string;
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "map_id": "office-3",
                     *       "version": 2,
                     *       "content_hash": "1feb9616bdac959eeff6727ad640bc19e0e577f3e7c8309b8a15ac0fbde0578c",
                     *       "created_at": "2026-01-05T10:00:00+00:00",
                     *       "map": {
                     *         "format": "quadloc.map/1",
                     *         "map_id": "office-3",
                     *         "name": "Office, third floor",
                     *         "version": 1,
                     *         "up_axis": [
                     *           0,
                     *           0,
                     *           1
                     *         ],
                     *         "categories": [
                     *           "chair",
                     *           "monitor",
                     *           "plant"
                     *         ],
                     *         "objects": [
                     *           {
                     *             "object_id": "chair-1",
                     *             "category": "chair",
                     *             "center": [
                     *               1.2,
                     *               0.4,
                     *               0.45
                     *             ],
                     *             "axes": [
                     *               0.3,
                     *               0.3,
                     *               0.45
                     *             ],
                     *             "quaternion_wxyz": [
                     *               1,
                     *               0,
                     *               0,
                     *               0
                     *             ]
                     *           },
                     *           {
                     *             "object_id": "monitor-1",
                     *             "category": "monitor",
                     *             "center": [
                     *               1.5,
                     *               1.1,
                     *               0.95
                     *             ],
                     *             "axes": [
                     *               0.3,
                     *               0.05,
                     *               0.2
                     *             ],
                     *             "quaternion_wxyz": [
                     *               0.9238795391929064,
                     *               0,
                     *               0,
                     *               0.38268341623423263
                     *             ]
                     *           },
                     *           {
                     *             "object_id": "plant-1",
                     *             "category": "plant",
                     *             "center": [
                     *               -0.4,
                     *               2,
                     *               0.6
                     *             ],
                     *             "axes": [
                     *               0.25,
                     *               0.25,
                     *               0.6
                     *             ],
                     *             "quaternion_wxyz": [
                     *               1,
                     *               0,
                     *               0,
                     *               0
                     *             ]
                     *           }
                     *         ],
                     *         "metadata": {
                     *           "source": "example"
                     *         }
                     *       }
                     *     }
                     */
                    "application/json": components["schemas"]["MapOut"];
                };
            };
            /** @description Malformed or unreadable body */
            400: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:malformed-json",
                     *       "title": "Malformed JSON body",
                     *       "status": 400,
                     *       "detail": "Malformed JSON body",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Conflict: map id taken, or an update lost a race */
            409: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:version-conflict",
                     *       "title": "Map version conflict",
                     *       "status": 409,
                     *       "detail": "Map version conflict",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Precondition failed: the map changed */
            412: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:precondition-failed",
                     *       "title": "Precondition failed: the map changed",
                     *       "status": 412,
                     *       "detail": "Precondition failed: the map changed",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Request body too large */
            413: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:payload-too-large",
                     *       "title": "Request body too large",
                     *       "status": 413,
                     *       "detail": "Request body too large",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Unsupported media type */
            415: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unsupported-media-type",
                     *       "title": "Unsupported media type",
                     *       "status": 415,
                     *       "detail": "Unsupported media type",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description If-Match header required */
            428: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:precondition-required",
                     *       "title": "If-Match header required",
                     *       "status": 428,
                     *       "detail": "If-Match header required",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    delete_map_v1_maps__map_id__delete: {
        parameters: {
            query?: never;
            header?: never;
            path: {
                /** @description Map id (pattern: quadloc.maps.model.MAP_ID_PATTERN). */
                map_id: string;
            };
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Successful Response */
            204: {
                headers: {
                    [name: string]: unknown;
                };
                content?: never;
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Conflict: map id taken, or an update lost a race */
            409: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:version-conflict",
                     *       "title": "Map version conflict",
                     *       "status": 409,
                     *       "detail": "Map version conflict",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    list_map_versions_v1_maps__map_id__versions_get: {
        parameters: {
            query?: never;
            header?: never;
            path: {
                /** @description Map id (pattern: quadloc.maps.model.MAP_ID_PATTERN). */
                map_id: string;
            };
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "map_id": "office-3",
                     *       "versions": [
                     *         {
                     *           "version": 1,
                     *           "content_hash": "1feb9616bdac959eeff6727ad640bc19e0e577f3e7c8309b8a15ac0fbde0578c",
                     *           "created_at": "2026-01-05T10:00:00+00:00"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/json": components["schemas"]["MapVersionsOut"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    start_build_v1_maps_build_post: {
        parameters: {
            query: {
                /** @description Id of the map to build. */
                map_id: string;
            };
            header?: {
                /** @description ETag of the map's latest version (only when the map exists). */
                "if-match"?: string | null;
            };
            path?: never;
            cookie?: never;
        };
        requestBody: {
            content: {
                /**
                 * @example {
                 *       "camera": {
                 *         "fx": 585,
                 *         "fy": 585,
                 *         "cx": 320,
                 *         "cy": 240,
                 *         "width": 640,
                 *         "height": 480
                 *       },
                 *       "name": "My room",
                 *       "holdout_every": 5,
                 *       "frames": [
                 *         {
                 *           "frame_id": "0001",
                 *           "world_from_camera": {
                 *             "quaternion_wxyz": [
                 *               1,
                 *               0,
                 *               0,
                 *               0
                 *             ],
                 *             "translation_m": [
                 *               0,
                 *               0,
                 *               0
                 *             ]
                 *           },
                 *           "detections": [
                 *             {
                 *               "label": "TV",
                 *               "ellipse": {
                 *                 "cx": 300,
                 *                 "cy": 200,
                 *                 "a": 80,
                 *                 "b": 40,
                 *                 "angle": 0.1
                 *               },
                 *               "sigma": 0.02
                 *             },
                 *             {
                 *               "label": "Chair",
                 *               "box": {
                 *                 "xmin": 10,
                 *                 "ymin": 200,
                 *                 "xmax": 110,
                 *                 "ymax": 420
                 *               }
                 *             }
                 *           ]
                 *         }
                 *       ]
                 *     }
                 */
                "application/json": components["schemas"]["RecordingIn"] | components["schemas"]["LegacyRecordingIn"];
            };
        };
        responses: {
            /** @description Successful Response */
            202: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "job_id": "5f0c3c1e-8a53-4b7c-9a56-0f1f7e3f2b11",
                     *       "map_id": "my-room",
                     *       "status": "queued",
                     *       "stage": "queued",
                     *       "percent": 0,
                     *       "objects_found": 0,
                     *       "created_at": "2026-11-23T20:00:00+00:00",
                     *       "updated_at": "2026-11-23T20:00:04+00:00"
                     *     }
                     */
                    "application/json": components["schemas"]["BuildJobOut"];
                };
            };
            /** @description Malformed or unreadable body */
            400: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:malformed-json",
                     *       "title": "Malformed JSON body",
                     *       "status": 400,
                     *       "detail": "Malformed JSON body",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Precondition failed: the map changed */
            412: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:precondition-failed",
                     *       "title": "Precondition failed: the map changed",
                     *       "status": 412,
                     *       "detail": "Precondition failed: the map changed",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Request body too large */
            413: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:payload-too-large",
                     *       "title": "Request body too large",
                     *       "status": 413,
                     *       "detail": "Request body too large",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Unsupported media type */
            415: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unsupported-media-type",
                     *       "title": "Unsupported media type",
                     *       "status": 415,
                     *       "detail": "Unsupported media type",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description If-Match header required */
            428: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:precondition-required",
                     *       "title": "If-Match header required",
                     *       "status": 428,
                     *       "detail": "If-Match header required",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    get_build_job_v1_build_jobs__job_id__get: {
        parameters: {
            query?: never;
            header?: never;
            path: {
                /** @description Job id. */
                job_id: string;
            };
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "job_id": "5f0c3c1e-8a53-4b7c-9a56-0f1f7e3f2b11",
                     *       "map_id": "my-room",
                     *       "status": "succeeded",
                     *       "stage": "done",
                     *       "percent": 100,
                     *       "objects_found": 9,
                     *       "map_version": 1,
                     *       "report": {
                     *         "objects": [
                     *           {
                     *             "object_id": "TV_1",
                     *             "label": "TV",
                     *             "association": "geometric",
                     *             "detections": [
                     *               {
                     *                 "frame_id": "0001",
                     *                 "frame_index": 0,
                     *                 "detection_index": 0
                     *               }
                     *             ],
                     *             "quality": {
                     *               "n_views": 69,
                     *               "view_spread_deg": 27,
                     *               "residual_cost": 12.3,
                     *               "rms_level_residual": 0.21,
                     *               "log_semi_axis_std": [
                     *                 0.05,
                     *                 0.4,
                     *                 0.6
                     *               ],
                     *               "center_std_m": 0.012,
                     *               "unconstrained_axes": [
                     *                 1,
                     *                 2
                     *               ],
                     *               "semi_axes_m": [
                     *                 0.42,
                     *                 0.34,
                     *                 0.18
                     *               ]
                     *             }
                     *           }
                     *         ],
                     *         "rejected_detections": [
                     *           {
                     *             "frame_id": "0003",
                     *             "frame_index": 2,
                     *             "detection_index": 1,
                     *             "label": "Chair",
                     *             "reason": "fits_no_object"
                     *           }
                     *         ],
                     *         "dropped_objects": [],
                     *         "counts": {
                     *           "frames": 300,
                     *           "detections": 1855,
                     *           "objects": 10,
                     *           "rejected_detections": 64
                     *         },
                     *         "refinement": {
                     *           "iterations": 12,
                     *           "initial_error": 5210.4,
                     *           "final_error": 1893.2,
                     *           "stopped_early": false,
                     *           "camera_poses_refined": true
                     *         },
                     *         "timings_s": {
                     *           "association": 0.8,
                     *           "refinement": 6.1,
                     *           "total": 7
                     *         },
                     *         "warnings": []
                     *       },
                     *       "created_at": "2026-11-23T20:00:00+00:00",
                     *       "updated_at": "2026-11-23T20:00:04+00:00"
                     *     }
                     */
                    "application/json": components["schemas"]["BuildJobOut"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    get_calibration_v1_maps__map_id__calibration_get: {
        parameters: {
            query?: {
                /** @description Map version (default: the latest). */
                version?: number | null;
            };
            header?: never;
            path: {
                /** @description Map id (pattern: quadloc.maps.model.MAP_ID_PATTERN). */
                map_id: string;
            };
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "map_id": "room",
                     *       "map_version": 1,
                     *       "key": "level_set",
                     *       "fit_frames": 100,
                     *       "covariance_scale": 106.9,
                     *       "shipped_covariance_scale": 3.06,
                     *       "s2_floor": 2.5,
                     *       "min_confidence": 0.36,
                     *       "before": {
                     *         "frames": 100,
                     *         "localized": 99,
                     *         "nees_frames": 85,
                     *         "mean_nees": 180.9,
                     *         "calibration_error": 0.067,
                     *         "calibration_error_floor": 0.066,
                     *         "calibration_error_sd": 0.021,
                     *         "mean_confidence": 0.82,
                     *         "success_rate": 0.86
                     *       },
                     *       "after": {
                     *         "frames": 100,
                     *         "localized": 99,
                     *         "nees_frames": 85,
                     *         "mean_nees": 6.46,
                     *         "calibration_error": 0.065,
                     *         "calibration_error_floor": 0.06,
                     *         "calibration_error_sd": 0.03,
                     *         "mean_confidence": 0.85,
                     *         "success_rate": 0.86
                     *       }
                     *     }
                     */
                    "application/json": components["schemas"]["CalibrationOut"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    calibrate_map_v1_maps__map_id__calibration_post: {
        parameters: {
            query?: {
                /** @description Map version (default: the latest). */
                version?: number | null;
            };
            header?: never;
            path: {
                /** @description Map id (pattern: quadloc.maps.model.MAP_ID_PATTERN). */
                map_id: string;
            };
            cookie?: never;
        };
        requestBody: {
            content: {
                /**
                 * @example {
                 *       "camera": {
                 *         "fx": 585,
                 *         "fy": 585,
                 *         "cx": 320,
                 *         "cy": 240,
                 *         "width": 640,
                 *         "height": 480
                 *       },
                 *       "name": "My room",
                 *       "holdout_every": 5,
                 *       "frames": [
                 *         {
                 *           "frame_id": "0001",
                 *           "world_from_camera": {
                 *             "quaternion_wxyz": [
                 *               1,
                 *               0,
                 *               0,
                 *               0
                 *             ],
                 *             "translation_m": [
                 *               0,
                 *               0,
                 *               0
                 *             ]
                 *           },
                 *           "detections": [
                 *             {
                 *               "label": "TV",
                 *               "ellipse": {
                 *                 "cx": 300,
                 *                 "cy": 200,
                 *                 "a": 80,
                 *                 "b": 40,
                 *                 "angle": 0.1
                 *               },
                 *               "sigma": 0.02
                 *             },
                 *             {
                 *               "label": "Chair",
                 *               "box": {
                 *                 "xmin": 10,
                 *                 "ymin": 200,
                 *                 "xmax": 110,
                 *                 "ymax": 420
                 *               }
                 *             }
                 *           ]
                 *         }
                 *       ]
                 *     }
                 */
                "application/json": components["schemas"]["RecordingIn"] | components["schemas"]["LegacyRecordingIn"];
            };
        };
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "map_id": "room",
                     *       "map_version": 1,
                     *       "key": "level_set",
                     *       "fit_frames": 100,
                     *       "covariance_scale": 106.9,
                     *       "shipped_covariance_scale": 3.06,
                     *       "s2_floor": 2.5,
                     *       "min_confidence": 0.36,
                     *       "before": {
                     *         "frames": 100,
                     *         "localized": 99,
                     *         "nees_frames": 85,
                     *         "mean_nees": 180.9,
                     *         "calibration_error": 0.067,
                     *         "calibration_error_floor": 0.066,
                     *         "calibration_error_sd": 0.021,
                     *         "mean_confidence": 0.82,
                     *         "success_rate": 0.86
                     *       },
                     *       "after": {
                     *         "frames": 100,
                     *         "localized": 99,
                     *         "nees_frames": 85,
                     *         "mean_nees": 6.46,
                     *         "calibration_error": 0.065,
                     *         "calibration_error_floor": 0.06,
                     *         "calibration_error_sd": 0.03,
                     *         "mean_confidence": 0.85,
                     *         "success_rate": 0.86
                     *       }
                     *     }
                     */
                    "application/json": components["schemas"]["CalibrationOut"];
                };
            };
            /** @description Malformed or unreadable body */
            400: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:malformed-json",
                     *       "title": "Malformed JSON body",
                     *       "status": 400,
                     *       "detail": "Malformed JSON body",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Request body too large */
            413: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:payload-too-large",
                     *       "title": "Request body too large",
                     *       "status": 413,
                     *       "detail": "Request body too large",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Unsupported media type */
            415: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unsupported-media-type",
                     *       "title": "Unsupported media type",
                     *       "status": 415,
                     *       "detail": "Unsupported media type",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    healthz_healthz_get: {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "status": "ok",
                     *       "checks": {}
                     *     }
                     */
                    "application/json": components["schemas"]["HealthOut"];
                };
            };
        };
    };
    readyz_readyz_get: {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "status": "ready",
                     *       "checks": {
                     *         "database": "ok",
                     *         "default_map": "chess v1"
                     *       }
                     *     }
                     */
                    "application/json": components["schemas"]["HealthOut"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    metrics_metrics_get: {
        parameters: {
            query?: never;
            header?: never;
            path?: never;
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Prometheus text exposition format. */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example # TYPE quadloc_localizations_total counter
                     *     quadloc_localizations_total{outcome="localized"} 42.0
                     */
                    "text/plain; version=1.0.0; charset=utf-8": string;
                };
            };
        };
    };
    create_session_v1_maps__map_id__sessions_post: {
        parameters: {
            query?: never;
            header?: never;
            path: {
                /** @description Map id (pattern: quadloc.maps.model.MAP_ID_PATTERN). */
                map_id: string;
            };
            cookie?: never;
        };
        requestBody: {
            content: {
                "application/json": components["schemas"]["SessionCreate"];
            };
        };
        responses: {
            /** @description Successful Response */
            201: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "session_id": "s-quadloc-1.Yk3v0cQ2c1xQm8Xo7b9m1g",
                     *       "url": "/v1/sessions/s-quadloc-1.Yk3v0cQ2c1xQm8Xo7b9m1g",
                     *       "map_id": "chess",
                     *       "map_version": 1,
                     *       "convention": "opencv",
                     *       "state": "initializing",
                     *       "frames": 0,
                     *       "idle_timeout_s": 300
                     *     }
                     */
                    "application/json": components["schemas"]["SessionOut"];
                };
            };
            /** @description Malformed or unreadable body */
            400: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:malformed-json",
                     *       "title": "Malformed JSON body",
                     *       "status": 400,
                     *       "detail": "Malformed JSON body",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Request body too large */
            413: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:payload-too-large",
                     *       "title": "Request body too large",
                     *       "status": 413,
                     *       "detail": "Request body too large",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Unsupported media type */
            415: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unsupported-media-type",
                     *       "title": "Unsupported media type",
                     *       "status": 415,
                     *       "detail": "Unsupported media type",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description This API key holds its quota of tracking sessions */
            429: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:session-quota",
                     *       "title": "This API key holds its quota of tracking sessions",
                     *       "status": 429,
                     *       "detail": "This API key holds its quota of tracking sessions",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    get_session_v1_sessions__session_id__get: {
        parameters: {
            query?: never;
            header?: never;
            path: {
                /** @description Session id returned at creation. */
                session_id: string;
            };
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "session_id": "s-quadloc-1.Yk3v0cQ2c1xQm8Xo7b9m1g",
                     *       "url": "/v1/sessions/s-quadloc-1.Yk3v0cQ2c1xQm8Xo7b9m1g",
                     *       "map_id": "chess",
                     *       "map_version": 1,
                     *       "convention": "opencv",
                     *       "state": "initializing",
                     *       "frames": 0,
                     *       "idle_timeout_s": 300
                     *     }
                     */
                    "application/json": components["schemas"]["SessionOut"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    delete_session_v1_sessions__session_id__delete: {
        parameters: {
            query?: never;
            header?: never;
            path: {
                /** @description Session id returned at creation. */
                session_id: string;
            };
            cookie?: never;
        };
        requestBody?: never;
        responses: {
            /** @description Successful Response */
            204: {
                headers: {
                    [name: string]: unknown;
                };
                content?: never;
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
    add_frames_v1_sessions__session_id__frames_post: {
        parameters: {
            query?: never;
            header?: never;
            path: {
                /** @description Session id returned at creation. */
                session_id: string;
            };
            cookie?: never;
        };
        requestBody: {
            content: {
                "application/json": components["schemas"]["SessionFramesIn"] | components["schemas"]["SessionFrameIn"];
            };
        };
        responses: {
            /** @description Successful Response */
            200: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "session_id": "s-quadloc-1.Yk3v0cQ2c1xQm8Xo7b9m1g",
                     *       "results": [
                     *         {
                     *           "frame_index": 0,
                     *           "frame_id": "0",
                     *           "timestamp": 0,
                     *           "state": "initializing",
                     *           "reason": "waiting_for_constraints",
                     *           "confidence": 0,
                     *           "inliers": [],
                     *           "n_usable_detections": 9,
                     *           "timings_ms": {
                     *             "total": 0.4
                     *           }
                     *         }
                     *       ]
                     *     }
                     */
                    "application/json": components["schemas"]["SessionFramesOut"];
                };
            };
            /** @description Malformed or unreadable body */
            400: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:malformed-json",
                     *       "title": "Malformed JSON body",
                     *       "status": 400,
                     *       "detail": "Malformed JSON body",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Missing or invalid API key */
            401: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unauthorized",
                     *       "title": "Missing or invalid API key",
                     *       "status": 401,
                     *       "detail": "Missing or invalid API key",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description API key lacks the required scope */
            403: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:forbidden",
                     *       "title": "API key lacks the required scope",
                     *       "status": 403,
                     *       "detail": "API key lacks the required scope",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Map (or version) not found */
            404: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:map-not-found",
                     *       "title": "Map not found",
                     *       "status": 404,
                     *       "detail": "Map not found",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Request body too large */
            413: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:payload-too-large",
                     *       "title": "Request body too large",
                     *       "status": 413,
                     *       "detail": "Request body too large",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Unsupported media type */
            415: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:unsupported-media-type",
                     *       "title": "Unsupported media type",
                     *       "status": 415,
                     *       "detail": "Unsupported media type",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Validation failed (validation-error, invalid-geometry or invalid-map); errors name the fields */
            422: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:validation-error",
                     *       "title": "Request validation failed",
                     *       "status": 422,
                     *       "detail": "detections[0].ellipse.a: Input should be greater than 0",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": [
                     *         {
                     *           "field": "detections[0].ellipse.a",
                     *           "message": "Input should be greater than 0"
                     *         }
                     *       ]
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
            /** @description Temporarily unavailable (solver busy or database unavailable); see Retry-After */
            503: {
                headers: {
                    [name: string]: unknown;
                };
                content: {
                    /**
                     * @example {
                     *       "type": "urn:quadloc:problem:busy",
                     *       "title": "Solver busy, retry later",
                     *       "status": 503,
                     *       "detail": "Solver busy, retry later",
                     *       "instance": "/v1/maps/chess",
                     *       "errors": []
                     *     }
                     */
                    "application/problem+json": components["schemas"]["Problem"];
                };
            };
        };
    };
}
