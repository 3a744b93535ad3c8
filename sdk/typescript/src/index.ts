/**
 * @quadloc/client: the TypeScript client of the QuadLoc relocalization service for web,
 * WebXR and React Native apps. ES module; no runtime dependency beyond `fetch`.
 *
 * - `QuadLocClient` (client.ts): maps, localize and batches, tracking sessions, map building;
 *   retries on 429 / 503 honouring Retry-After; timeouts; cancellation (AbortSignal).
 * - errors (errors.ts): one class per problem kind, carrying the RFC 9457 document.
 * - models (models.ts): the wire types, generated from docs/openapi.json.
 * - geometry (geometry.ts): box / mask -> ellipse, poses, conventions, quaternion orders,
 *   matrix layouts, Unity; webxr.ts and three.ts: the web's conventions.
 */
export * from "./client.js";
export * from "./errors.js";
export * from "./geometry.js";
export * from "./models.js";
export * from "./retry.js";
export * from "./three.js";
export * from "./webxr.js";
