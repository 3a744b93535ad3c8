// QuadLocClient: the HTTP client of the QuadLoc API for Unity and .NET apps (.NET Standard
// 2.0 APIs only: System.Net.Http, Tasks; C# 7.2), with retries on 429 / 503 honouring
// Retry-After, a timeout per attempt, cancellation (CancellationToken) and typed exceptions
// carrying the problem document.
//
//   using (var client = new QuadLocClient(new QuadLocClientOptions { BaseUrl = "http://127.0.0.1:8000" }))
//   {
//       LocalizeResponse answer = await client.LocalizeAsync("chess", request);
//       if (answer.Localized) Use(answer.WorldFromCamera);   // row-major Matrix, metres
//   }
//
// "Not localized" is a normal answer (Localized == false, Reason); errors throw ApiException
// subclasses (Errors.cs).
using System;
using System.Collections.Generic;
using System.Linq;
using System.Net;
using System.Net.Http;
using System.Net.Sockets;
using System.Text;
using System.Threading;
using System.Threading.Tasks;

namespace QuadLoc.Client
{
    /// <summary>How a client is set up.</summary>
    public sealed class QuadLocClientOptions
    {
        /// <summary>The server, e.g. http://127.0.0.1:8000 (default).</summary>
        public string BaseUrl { get; set; } = "http://127.0.0.1:8000";
        /// <summary>API key (scope read, or read+write); null for an open loopback server.</summary>
        public string ApiKey { get; set; }
        /// <summary>Send the key as X-API-Key instead of Authorization: Bearer.</summary>
        public bool UseXApiKeyHeader { get; set; }
        /// <summary>Timeout of one attempt (connection, request and the whole answer). Default 30 s.</summary>
        public TimeSpan Timeout { get; set; } = TimeSpan.FromSeconds(30);
        public RetryPolicy Retry { get; set; } = new RetryPolicy();
        /// <summary>The HTTP handler (default HttpClientHandler): a mock in tests.</summary>
        public HttpMessageHandler Handler { get; set; }
    }

    /// <summary>A map version with its document and the response's ETag.</summary>
    public sealed class MapRecord
    {
        public string MapId { get; set; }
        public long Version { get; set; }
        public string ContentHash { get; set; }
        public string CreatedAt { get; set; }
        /// <summary>The map document (docs/maps.md).</summary>
        public JsonValue Map { get; set; }
        /// <summary>The ETag to send as If-Match when updating this version.</summary>
        public string ETag { get; set; }
    }

    /// <summary>The QuadLoc client. One per server; thread-safe; dispose it (it owns an HttpClient).</summary>
    public sealed class QuadLocClient : IDisposable
    {
        public const string SdkVersion = "0.1.0";

        private readonly HttpClient _http;
        private readonly string _baseUrl;
        private readonly RetryPolicy _retry;
        private readonly TimeSpan _timeout;
        private readonly KeyValuePair<string, string>? _auth;

        public QuadLocClient(QuadLocClientOptions options = null)
        {
            options = options ?? new QuadLocClientOptions();
            if (options.BaseUrl == null || !(options.BaseUrl.StartsWith("http://", StringComparison.Ordinal) || options.BaseUrl.StartsWith("https://", StringComparison.Ordinal)))
                throw new InvalidArgumentException("BaseUrl", "must start with http:// or https://, got '" + options.BaseUrl + "'");
            if (options.Timeout <= TimeSpan.Zero) throw new InvalidArgumentException("Timeout", "must be > 0");
            _baseUrl = options.BaseUrl.TrimEnd('/');
            _retry = options.Retry ?? new RetryPolicy();
            _retry.Validate();
            _timeout = options.Timeout;
            if (options.ApiKey != null)
            {
                if (options.ApiKey.Trim().Length == 0) throw new InvalidArgumentException("ApiKey", "must be a non-empty string or null");
                _auth = options.UseXApiKeyHeader
                    ? new KeyValuePair<string, string>("X-API-Key", options.ApiKey.Trim())
                    : new KeyValuePair<string, string>("Authorization", "Bearer " + options.ApiKey.Trim());
            }
            _http = options.Handler != null ? new HttpClient(options.Handler, false) : new HttpClient();
            _http.Timeout = System.Threading.Timeout.InfiniteTimeSpan; // ours is per attempt
        }

        public string BaseUrl { get { return _baseUrl; } }

        public void Dispose() { _http.Dispose(); }

        // ------------------------------------------------------------------------- transport

        private sealed class Call
        {
            public HttpMethod Method;
            public string Path;
            public string Query;
            public string Body;
            public Dictionary<string, string> Headers = new Dictionary<string, string>();
            public bool Idempotent;
        }

        private sealed class Answer
        {
            public int Status;
            public string Text;
            public Dictionary<string, string> Headers;
            public string Url;
            public string Method;
        }

        private static string Segment(string field, string value)
        {
            if (string.IsNullOrEmpty(value)) throw new InvalidArgumentException(field, "must be a non-empty string");
            return Uri.EscapeDataString(value);
        }

        private static string Query(params KeyValuePair<string, string>[] items)
        {
            var parts = items.Where(kv => kv.Value != null).Select(kv => Uri.EscapeDataString(kv.Key) + "=" + Uri.EscapeDataString(kv.Value)).ToList();
            return parts.Count == 0 ? null : string.Join("&", parts);
        }

        private static KeyValuePair<string, string> Q(string key, string value) { return new KeyValuePair<string, string>(key, value); }

        private static string Version(string field, long? version)
        {
            if (version == null) return null;
            if (version < 1) throw new InvalidArgumentException(field, "must be an integer >= 1, got " + version);
            return version.Value.ToString(System.Globalization.CultureInfo.InvariantCulture);
        }

        private static string EtagValue(string etag)
        {
            var e = etag.Trim();
            return e.StartsWith("\"", StringComparison.Ordinal) || e.StartsWith("W/\"", StringComparison.Ordinal) ? e : "\"" + e + "\"";
        }

        private static bool NotSent(Exception e)
        {
            for (var x = e; x != null; x = x.InnerException)
            {
                var s = x as SocketException;
                if (s != null && (s.SocketErrorCode == SocketError.ConnectionRefused || s.SocketErrorCode == SocketError.HostNotFound)) return true;
                var w = x as WebException;
                if (w != null && (w.Status == WebExceptionStatus.ConnectFailure || w.Status == WebExceptionStatus.NameResolutionFailure)) return true;
            }
            return false;
        }

        private async Task<Answer> SendAsync(Call call, CancellationToken ct, TimeSpan? timeout = null)
        {
            string url = _baseUrl + call.Path + (call.Query != null ? "?" + call.Query : "");
            string method = call.Method.Method;
            var perAttempt = timeout ?? _timeout;
            for (int attempt = 1; ; attempt++)
            {
                ct.ThrowIfCancellationRequested();
                Answer answer = null;
                Exception failure = null;
                bool timedOut = false;
                using (var cts = CancellationTokenSource.CreateLinkedTokenSource(ct))
                using (var request = new HttpRequestMessage(call.Method, url))
                {
                    cts.CancelAfter(perAttempt);
                    request.Headers.TryAddWithoutValidation("Accept", "application/json, application/problem+json");
                    request.Headers.TryAddWithoutValidation("User-Agent", "quadloc-csharp/" + SdkVersion);
                    if (_auth.HasValue) request.Headers.TryAddWithoutValidation(_auth.Value.Key, _auth.Value.Value);
                    foreach (var h in call.Headers) request.Headers.TryAddWithoutValidation(h.Key, h.Value);
                    if (call.Body != null) request.Content = new StringContent(call.Body, Encoding.UTF8, "application/json");
                    try
                    {
                        using (var response = await _http.SendAsync(request, HttpCompletionOption.ResponseContentRead, cts.Token).ConfigureAwait(false))
                        {
                            var text = response.Content != null ? await response.Content.ReadAsStringAsync().ConfigureAwait(false) : "";
                            var headers = new Dictionary<string, string>(StringComparer.OrdinalIgnoreCase);
                            foreach (var h in response.Headers) headers[h.Key.ToLowerInvariant()] = string.Join(", ", h.Value);
                            if (response.Content != null)
                                foreach (var h in response.Content.Headers) headers[h.Key.ToLowerInvariant()] = string.Join(", ", h.Value);
                            answer = new Answer { Status = (int)response.StatusCode, Text = text, Headers = headers, Url = url, Method = method };
                        }
                    }
                    catch (OperationCanceledException e)
                    {
                        if (ct.IsCancellationRequested) throw;
                        timedOut = true;
                        failure = e;
                    }
                    catch (HttpRequestException e) { failure = e; }
                    catch (WebException e) { failure = e; }
                    catch (SocketException e) { failure = e; }
                }
                if (answer == null)
                {
                    bool retryable = attempt < _retry.MaxAttempts && (call.Idempotent || (!timedOut && NotSent(failure)));
                    if (retryable)
                    {
                        await Task.Delay(TimeSpan.FromSeconds(_retry.BackoffSeconds(attempt)), ct).ConfigureAwait(false);
                        continue;
                    }
                    if (timedOut) throw new QuadLocTimeoutException("no answer within " + perAttempt.TotalMilliseconds + " ms", method, url, attempt, failure);
                    throw new TransportException(Describe(failure), method, url, attempt, failure);
                }
                if (answer.Status < 400) return answer;
                if (attempt < _retry.MaxAttempts)
                {
                    string retryAfter;
                    answer.Headers.TryGetValue("retry-after", out retryAfter);
                    var delay = _retry.DelayForResponse(answer.Status, retryAfter, attempt);
                    if (delay.HasValue)
                    {
                        await Task.Delay(TimeSpan.FromSeconds(delay.Value), ct).ConfigureAwait(false);
                        continue;
                    }
                }
                string ctype;
                answer.Headers.TryGetValue("content-type", out ctype);
                throw ApiException.FromResponse(answer.Status, method, url, ctype, answer.Text, answer.Headers, attempt);
            }
        }

        private static string Describe(Exception e)
        {
            var parts = new List<string>();
            for (var x = e; x != null; x = x.InnerException) parts.Add(x.Message);
            return string.Join(": ", parts.Distinct());
        }

        private static JsonValue Json(Answer a)
        {
            try { return JsonValue.Parse(a.Text); }
            catch (FormatException e)
            {
                throw new QuadLocException(a.Method + " " + a.Url + ": the server answered " + a.Status + " with a body that is not JSON", e);
            }
        }

        private static MapRecord Record(Answer a)
        {
            var j = Json(a);
            string etag;
            a.Headers.TryGetValue("etag", out etag);
            var created = j.Get("created_at");
            return new MapRecord
            {
                MapId = j["map_id"].AsString(),
                Version = j["version"].AsLong(),
                ContentHash = j["content_hash"].AsString(),
                CreatedAt = created == null || created.IsNull ? null : created.AsString(),
                Map = j["map"],
                ETag = etag,
            };
        }

        private static string Body(string field, JsonValue value)
        {
            try { return value.ToJson(field); }
            catch (ArgumentException e)
            {
                var path = e.Message.Split(new[] { ": " }, 2, StringSplitOptions.None)[0];
                throw new InvalidArgumentException(path, e.Message.Substring(Math.Min(e.Message.Length, path.Length + 2)));
            }
        }

        private Task<Answer> Get(string path, CancellationToken ct, string query = null)
        {
            return SendAsync(new Call { Method = HttpMethod.Get, Path = path, Query = query, Idempotent = true }, ct);
        }

        private static string MapPath(string mapId) { return "/v1/maps/" + Segment("mapId", mapId); }

        // ------------------------------------------------------------------------- service

        /// <summary>GET /healthz: the process is alive.</summary>
        public async Task<HealthOut> HealthzAsync(CancellationToken ct = default(CancellationToken))
        {
            return HealthOut.FromJson(Json(await Get("/healthz", ct).ConfigureAwait(false)));
        }

        /// <summary>GET /readyz: database reachable, default map loadable (503: ServiceUnavailableException).</summary>
        public async Task<HealthOut> ReadyzAsync(CancellationToken ct = default(CancellationToken))
        {
            return HealthOut.FromJson(Json(await Get("/readyz", ct).ConfigureAwait(false)));
        }

        /// <summary>GET /metrics: the Prometheus text exposition.</summary>
        public async Task<string> MetricsAsync(CancellationToken ct = default(CancellationToken))
        {
            return (await Get("/metrics", ct).ConfigureAwait(false)).Text;
        }

        // ------------------------------------------------------------------------- maps

        /// <summary>Every map with its latest version (GET /v1/maps).</summary>
        public async Task<List<MapSummaryOut>> ListMapsAsync(CancellationToken ct = default(CancellationToken))
        {
            return MapListOut.FromJson(Json(await Get("/v1/maps", ct).ConfigureAwait(false))).Maps;
        }

        /// <summary>The latest (or the given) version of a map, with its ETag (GET /v1/maps/{id}).</summary>
        public async Task<MapRecord> GetMapAsync(string mapId, long? version = null, CancellationToken ct = default(CancellationToken))
        {
            return Record(await Get(MapPath(mapId), ct, Query(Q("version", Version("version", version)))).ConfigureAwait(false));
        }

        /// <summary>The map document of the latest (or the given) version: what CreateMapAsync imports.</summary>
        public async Task<JsonValue> ExportMapAsync(string mapId, long? version = null, CancellationToken ct = default(CancellationToken))
        {
            return (await GetMapAsync(mapId, version, ct).ConfigureAwait(false)).Map;
        }

        /// <summary>Every stored version of a map, ascending (GET /v1/maps/{id}/versions).</summary>
        public async Task<List<MapVersionOut>> ListVersionsAsync(string mapId, CancellationToken ct = default(CancellationToken))
        {
            return MapVersionsOut.FromJson(Json(await Get(MapPath(mapId) + "/versions", ct).ConfigureAwait(false))).Versions;
        }

        /// <summary>Imports a map document (docs/maps.md) as a new map, version 1 (POST /v1/maps).
        /// ConflictException (map-exists) when the id is taken; ValidationException (invalid-map) naming fields.</summary>
        public async Task<MapRecord> CreateMapAsync(JsonValue document, CancellationToken ct = default(CancellationToken))
        {
            var call = new Call { Method = HttpMethod.Post, Path = "/v1/maps", Body = Body("map", document) };
            return Record(await SendAsync(call, ct).ConfigureAwait(false));
        }

        /// <summary>Creates map <paramref name="mapId"/> from the 7-Scenes Chess format (POST /v1/maps:import-chess).</summary>
        public async Task<MapRecord> ImportChessMapAsync(JsonValue chess, string mapId, string name = null, CancellationToken ct = default(CancellationToken))
        {
            Segment("mapId", mapId);
            var call = new Call { Method = HttpMethod.Post, Path = "/v1/maps:import-chess", Query = Query(Q("map_id", mapId), Q("name", name)), Body = Body("chess", chess) };
            return Record(await SendAsync(call, ct).ConfigureAwait(false));
        }

        /// <summary>Replaces a map by version n + 1 (PUT /v1/maps/{id}). <paramref name="ifMatch"/>:
        /// the ETag of the version edited; stale: PreconditionFailedException.</summary>
        public async Task<MapRecord> UpdateMapAsync(string mapId, JsonValue document, string ifMatch, CancellationToken ct = default(CancellationToken))
        {
            if (string.IsNullOrWhiteSpace(ifMatch)) throw new InvalidArgumentException("ifMatch", "must be the ETag of the version edited (updates never silently overwrite)");
            var call = new Call { Method = HttpMethod.Put, Path = MapPath(mapId), Body = Body("map", document) };
            call.Headers["If-Match"] = EtagValue(ifMatch);
            return Record(await SendAsync(call, ct).ConfigureAwait(false));
        }

        /// <summary>Deletes a map and all its versions (DELETE /v1/maps/{id}).</summary>
        public async Task DeleteMapAsync(string mapId, CancellationToken ct = default(CancellationToken))
        {
            await SendAsync(new Call { Method = HttpMethod.Delete, Path = MapPath(mapId) }, ct).ConfigureAwait(false);
        }

        // ------------------------------------------------------------------------- localization

        /// <summary>Localizes one frame against the latest version of <paramref name="mapId"/>
        /// (or <paramref name="mapVersion"/>) (POST /v1/maps/{id}/localize). Retried on 429 / 503
        /// and, being a pure computation, after network failures and timeouts.</summary>
        public async Task<LocalizeResponse> LocalizeAsync(string mapId, LocalizeRequest request, long? mapVersion = null,
                                                          CancellationToken ct = default(CancellationToken))
        {
            if (request == null) throw new InvalidArgumentException("request", "must not be null");
            var call = new Call
            {
                Method = HttpMethod.Post, Path = MapPath(mapId) + "/localize", Query = Query(Q("version", Version("mapVersion", mapVersion))),
                Body = Body("request", request.ToJson()), Idempotent = true,
            };
            return LocalizeResponse.FromJson(Json(await SendAsync(call, ct).ConfigureAwait(false)));
        }

        /// <summary>Several frames in one request, solved in order against one map version.</summary>
        public async Task<BatchLocalizeResponse> LocalizeBatchAsync(string mapId, IList<LocalizeRequest> frames, long? mapVersion = null,
                                                                    CancellationToken ct = default(CancellationToken))
        {
            if (frames == null || frames.Count == 0) throw new InvalidArgumentException("frames", "must be a non-empty list of localize requests");
            var body = new BatchLocalizeRequest { Frames = frames.ToList() };
            var call = new Call
            {
                Method = HttpMethod.Post, Path = MapPath(mapId) + "/localize:batch", Query = Query(Q("version", Version("mapVersion", mapVersion))),
                Body = Body("batch", body.ToJson()), Idempotent = true,
            };
            return BatchLocalizeResponse.FromJson(Json(await SendAsync(call, ct).ConfigureAwait(false)));
        }

        // ------------------------------------------------------------------------- tracking

        /// <summary>Starts a tracking session (POST /v1/maps/{id}/sessions): camera, the camera
        /// axes Convention of every odometry pose and answer ("opengl" for ARKit / ARCore /
        /// AR Foundation poses converted to right-handed), options. docs/tracking.md.</summary>
        public async Task<TrackingSession> StartSessionAsync(string mapId, SessionCreate body, CancellationToken ct = default(CancellationToken))
        {
            if (body == null) throw new InvalidArgumentException("body", "must not be null");
            var call = new Call { Method = HttpMethod.Post, Path = MapPath(mapId) + "/sessions", Body = Body("session", body.ToJson()) };
            return new TrackingSession(this, SessionOut.FromJson(Json(await SendAsync(call, ct).ConfigureAwait(false))));
        }

        /// <summary>A session's state (GET /v1/sessions/{id}); NotFoundException once expired.</summary>
        public async Task<SessionOut> GetSessionAsync(string sessionId, CancellationToken ct = default(CancellationToken))
        {
            return SessionOut.FromJson(Json(await Get("/v1/sessions/" + Segment("sessionId", sessionId), ct).ConfigureAwait(false)));
        }

        /// <summary>Ends a session (DELETE /v1/sessions/{id}).</summary>
        public async Task DeleteSessionAsync(string sessionId, CancellationToken ct = default(CancellationToken))
        {
            await SendAsync(new Call { Method = HttpMethod.Delete, Path = "/v1/sessions/" + Segment("sessionId", sessionId) }, ct).ConfigureAwait(false);
        }

        /// <summary>Sends tracking frames (one, or a recording of up to 900 in time order),
        /// validated whole before any is fused. Not replayed after a network failure.</summary>
        public async Task<List<SessionFrameOut>> AddSessionFramesAsync(string sessionId, IList<SessionFrameIn> frames,
                                                                       CancellationToken ct = default(CancellationToken))
        {
            if (frames == null || frames.Count == 0) throw new InvalidArgumentException("frames", "must be a non-empty list of session frames");
            var body = frames.Count == 1 ? Body("frame", frames[0].ToJson()) : Body("frames", new SessionFramesIn { Frames = frames.ToList() }.ToJson());
            var call = new Call { Method = HttpMethod.Post, Path = "/v1/sessions/" + Segment("sessionId", sessionId) + "/frames", Body = body };
            return SessionFramesOut.FromJson(Json(await SendAsync(call, ct).ConfigureAwait(false))).Results;
        }

        // ------------------------------------------------------------------------- map building

        /// <summary>Builds a map from a recording (POST /v1/maps:build, docs/map_building.md).
        /// With <paramref name="wait"/> the job is polled until it ends: returns the succeeded
        /// job (MapVersion, Report) or throws BuildFailedException (Job.Error).
        /// <paramref name="onProgress"/> runs whenever the stage, percent or object count
        /// changes. For an existing map pass <paramref name="ifMatch"/> (its ETag).</summary>
        public async Task<BuildJobOut> BuildMapAsync(JsonValue recording, string mapId, string ifMatch = null, bool wait = true,
                                                     Action<BuildJobOut> onProgress = null, TimeSpan? pollInterval = null,
                                                     TimeSpan? waitTimeout = null, CancellationToken ct = default(CancellationToken))
        {
            Segment("mapId", mapId);
            var call = new Call { Method = HttpMethod.Post, Path = "/v1/maps:build", Query = Query(Q("map_id", mapId)), Body = Body("recording", recording) };
            if (ifMatch != null) call.Headers["If-Match"] = EtagValue(ifMatch);
            var answer = await SendAsync(call, ct).ConfigureAwait(false);
            var job = BuildJobOut.FromJson(Json(answer));
            string location;
            if (!answer.Headers.TryGetValue("location", out location)) location = "/v1/build-jobs/" + Uri.EscapeDataString(job.JobId);
            if (onProgress != null) onProgress(job);
            if (!wait) return job;
            var poll = pollInterval ?? TimeSpan.FromMilliseconds(500);
            var deadline = DateTime.UtcNow + (waitTimeout ?? TimeSpan.FromMinutes(10));
            var last = job.Stage + "|" + job.Percent + "|" + job.ObjectsFound;
            while (job.Status != "succeeded" && job.Status != "failed")
            {
                if (DateTime.UtcNow > deadline)
                    throw new BuildFailedException("build job " + job.JobId + " not finished in time (still " + job.Status + "); poll it with GetBuildJobAsync", job);
                await Task.Delay(poll, ct).ConfigureAwait(false);
                job = await GetBuildJobAsync(location, ct).ConfigureAwait(false);
                var now = job.Stage + "|" + job.Percent + "|" + job.ObjectsFound;
                if (onProgress != null && now != last) onProgress(job);
                last = now;
            }
            if (job.Status == "failed")
            {
                var reason = job.Error != null ? job.Error.Reason : "?";
                var detail = job.Error != null ? job.Error.Detail : "";
                throw new BuildFailedException("build job " + job.JobId + " failed: " + reason + ": " + detail, job);
            }
            return job;
        }

        /// <summary>Fits, stores and returns a map version's own calibration (POST
        /// /v1/maps/{id}/calibration, docs/map_building.md "Calibrating the map") from the
        /// recording it was built from (with holdout_every). Synchronous: <paramref name="timeout"/>
        /// (default 10 minutes) bounds the wait (1,000 held-out frames take about 25 s).
        /// Not replayed after a network failure.</summary>
        public async Task<CalibrationOut> CalibrateMapAsync(string mapId, JsonValue recording, long? version = null,
                                                            TimeSpan? timeout = null, CancellationToken ct = default(CancellationToken))
        {
            var call = new Call { Method = HttpMethod.Post, Path = MapPath(mapId) + "/calibration",
                                  Query = Query(Q("version", Version("version", version))), Body = Body("recording", recording) };
            return CalibrationOut.FromJson(Json(await SendAsync(call, ct, timeout ?? TimeSpan.FromMinutes(10)).ConfigureAwait(false)));
        }

        /// <summary>A map version's stored calibration (GET /v1/maps/{id}/calibration;
        /// NotFoundException when it has none: the shipped constants apply).</summary>
        public async Task<CalibrationOut> GetCalibrationAsync(string mapId, long? version = null, CancellationToken ct = default(CancellationToken))
        {
            return CalibrationOut.FromJson(Json(await Get(MapPath(mapId) + "/calibration", ct, Query(Q("version", Version("version", version)))).ConfigureAwait(false)));
        }

        /// <summary>A build job's state, by id or by its Location path (GET /v1/build-jobs/{id}).</summary>
        public async Task<BuildJobOut> GetBuildJobAsync(string jobIdOrLocation, CancellationToken ct = default(CancellationToken))
        {
            if (string.IsNullOrEmpty(jobIdOrLocation)) throw new InvalidArgumentException("jobId", "must be a non-empty string");
            var path = jobIdOrLocation.StartsWith("/", StringComparison.Ordinal) ? jobIdOrLocation : "/v1/build-jobs/" + Segment("jobId", jobIdOrLocation);
            return BuildJobOut.FromJson(Json(await Get(path, ct).ConfigureAwait(false)));
        }
    }

    /// <summary>A live tracking session (docs/tracking.md); Info is the server's session document.</summary>
    public sealed class TrackingSession
    {
        public QuadLocClient Client { get; private set; }
        public string SessionId { get; private set; }
        public SessionOut Info { get; private set; }

        public TrackingSession(QuadLocClient client, SessionOut info)
        {
            Client = client; Info = info; SessionId = info.SessionId;
        }

        /// <summary>Sends one frame; returns its answer (State, WorldFromCamera, WorldFromOdom).</summary>
        public async Task<SessionFrameOut> AddFrameAsync(SessionFrameIn frame, CancellationToken ct = default(CancellationToken))
        {
            return (await Client.AddSessionFramesAsync(SessionId, new[] { frame }, ct).ConfigureAwait(false))[0];
        }

        /// <summary>Sends recorded frames (time order, at most 900) in one request.</summary>
        public Task<List<SessionFrameOut>> AddFramesAsync(IList<SessionFrameIn> frames, CancellationToken ct = default(CancellationToken))
        {
            return Client.AddSessionFramesAsync(SessionId, frames, ct);
        }

        /// <summary>The session's state on the server (updates Info).</summary>
        public async Task<SessionOut> GetAsync(CancellationToken ct = default(CancellationToken))
        {
            Info = await Client.GetSessionAsync(SessionId, ct).ConfigureAwait(false);
            return Info;
        }

        /// <summary>Ends the session on the server.</summary>
        public Task CloseAsync(CancellationToken ct = default(CancellationToken))
        {
            return Client.DeleteSessionAsync(SessionId, ct);
        }
    }
}
