// The live scenarios (the TypeScript suite's): against QUADLOC_URL (open, demo map "chess") and
// QUADLOC_KEYED_URL (keys QUADLOC_KEY_RW / QUADLOC_KEY_READ, one session, a 20 kB body limit).
using System;
using System.Collections.Generic;
using System.Linq;
using System.Threading.Tasks;
using QuadLoc.Client;

public static partial class Tests
{
    static readonly string Run = "cs" + System.Diagnostics.Process.GetCurrentProcess().Id;
    static string Url { get { return Environment.GetEnvironmentVariable("QUADLOC_URL"); } }
    static string KeyedUrl { get { return Environment.GetEnvironmentVariable("QUADLOC_KEYED_URL"); } }

    static QuadLocClient Live(string apiKey = null, bool keyed = false, RetryPolicy retry = null)
    {
        return new QuadLocClient(new QuadLocClientOptions { BaseUrl = keyed ? KeyedUrl : Url, ApiKey = apiKey, Retry = retry ?? new RetryPolicy() });
    }

    static T Expect<T>(Func<Task> call, string slug, string field = null) where T : ApiException
    {
        var e = Check.ThrowsAsync(call, slug);
        Check.True(e is T, slug + ": expected " + typeof(T).Name + ", got " + e.GetType().Name + ": " + e.Message);
        var api = (T)e;
        Check.Equal(slug, api.Slug, "slug of " + api.Message);
        if (field != null) Check.True(api.Fields.Contains(field), slug + ": fields " + string.Join(",", api.Fields) + " lack " + field);
        return api;
    }

    [Test(Needs = "QUADLOC_URL")]
    public static async Task LiveDemoFrameLocalizesAndBatches()
    {
        using (var client = Live())
        {
            var answer = await client.LocalizeAsync("chess", Demo());
            Check.True(answer.Localized, "localized (" + answer.Reason + ")");
            var t = answer.WorldFromCamera.TranslationM;
            Check.True(Math.Sqrt(Math.Pow(t[0] + 0.02, 2) + Math.Pow(t[1] + 0.307, 2) + Math.Pow(t[2] - 0.77, 2)) < 0.05, "near the true centre");
            Check.True(answer.Confidence > 0.5, "confidence");
            Check.Close(answer.WorldFromCamera.MatrixColumnMajor, Geometry.ColumnMajorFromMatrix(answer.WorldFromCamera.Matrix()), 0, "column-major");
            var unity = Geometry.UnityPoseFromWorldFromCamera(answer.WorldFromCamera.Matrix());
            Check.Close(unity.Position, new[] { t[0], t[2], t[1] }, 1e-12, "Unity position of a Z-up map swaps y and z");
            var a = Demo(); a.FrameId = "a";
            var b = Demo(); b.FrameId = "b";
            var batch = await client.LocalizeBatchAsync("chess", new[] { a, b });
            Check.Equal("a,b", string.Join(",", batch.Results.Select(r => r.FrameId)), "order");
            Check.True(batch.Results.All(r => r.Localized), "all localized");
        }
    }

    [Test(Needs = "QUADLOC_URL")]
    public static async Task LiveMapsImportGetVersionsUpdateExportDelete()
    {
        using (var client = Live())
        {
            var office = ReadJson("docs/examples/office_map.json");
            var mapId = "office-" + Run;
            office.Set("map_id", mapId);
            var created = await client.CreateMapAsync(office);
            Check.Equal(1L, created.Version, "version");
            Check.Equal("\"" + created.ContentHash + "\"", created.ETag, "etag");
            Check.True((await client.ListMapsAsync()).Any(m => m.MapId == mapId), "listed");
            var latest = await client.GetMapAsync(mapId);
            var edited = JsonValue.Parse(latest.Map.ToString());
            edited.Set("name", "Office, 3rd floor");
            Check.Equal(2L, (await client.UpdateMapAsync(mapId, edited, latest.ETag)).Version, "updated");
            Check.Equal("1,2", string.Join(",", (await client.ListVersionsAsync(mapId)).Select(v => v.Version)), "versions");
            Check.Equal("Office, 3rd floor", (await client.ExportMapAsync(mapId))["name"].AsString(), "export");
            Expect<PreconditionFailedException>(() => client.UpdateMapAsync(mapId, latest.Map, latest.ETag), "precondition-failed");
            Expect<ConflictException>(() => client.CreateMapAsync(office), "map-exists");
            await client.DeleteMapAsync(mapId);
            Expect<NotFoundException>(() => client.GetMapAsync(mapId), "map-not-found");
            var copy = await client.ImportChessMapAsync(ReadJson("tests/support/data/chess_scene.json"), "chess-" + Run, "Chess copy");
            Check.Equal("Chess copy", copy.Map["name"].AsString(), "chess import");
            await client.DeleteMapAsync("chess-" + Run);
        }
    }

    [Test(Needs = "QUADLOC_URL")]
    public static async Task LiveSessionTracksTheShippedRecording()
    {
        var rec = ReadJson("docs/examples/track_chess.json");
        using (var client = Live())
        {
            var session = await client.StartSessionAsync("chess", new SessionCreate { Camera = CameraIn.FromJson(rec["camera"]), Convention = "opengl" });
            int tracking = 0, within = 0, i = 0;
            double[,] worldFromOdom = null;
            foreach (var f in rec["frames"].Items)
            {
                var frame = SessionFrameIn.FromJson(f);
                // an ARKit / ARCore app's odometry: OpenGL camera axes
                frame.OdomFromCamera = Geometry.PoseInput(Geometry.WorldFromCameraOpencvToOpengl(Geometry.ToArray(frame.OdomFromCamera.Matrix)));
                var r = await session.AddFrameAsync(frame);
                Check.Equal((long)i, r.FrameIndex, "frame index");
                if (r.State == "tracking")
                {
                    tracking++;
                    var truth = M(rec["ground_truth_world_from_camera"][i]);
                    var t = r.WorldFromCamera.TranslationM;
                    if (Math.Sqrt(Math.Pow(t[0] - truth[0, 3], 2) + Math.Pow(t[1] - truth[1, 3], 2) + Math.Pow(t[2] - truth[2, 3], 2)) < 0.1) within++;
                    worldFromOdom = r.WorldFromOdom.Matrix();
                }
                i++;
            }
            Check.True(tracking >= 60, "tracking on " + tracking + " frames");
            Check.True(within >= 0.9 * tracking, within + " of " + tracking + " within 10 cm");
            var last = rec["frames"].Count - 1;
            var odom = M(rec["frames"][last]["odom_from_camera"]["matrix"]);
            var mapped = Geometry.TransformPoint(worldFromOdom, new[] { odom[0, 3], odom[1, 3], odom[2, 3] });
            var gt = M(rec["ground_truth_world_from_camera"][last]);
            Check.Close(mapped, new[] { gt[0, 3], gt[1, 3], gt[2, 3] }, 0.1, "world_from_odom maps the odometry onto the map");
            var info = await session.GetAsync();
            Check.Equal((long)rec["frames"].Count, info.Frames, "frames");
            await session.CloseAsync();
            Expect<NotFoundException>(() => client.GetSessionAsync(session.SessionId), "session-not-found");
        }
    }

    [Test(Needs = "QUADLOC_URL")]
    public static async Task LiveBuildJobCompletesWithProgress()
    {
        var recording = ReadJson("sdk/test-vectors/build_recording.json");
        var mapId = "built-" + Run;
        var progress = new List<BuildJobOut>();
        using (var client = Live())
        {
            var job = await client.BuildMapAsync(recording, mapId, onProgress: progress.Add, pollInterval: TimeSpan.FromMilliseconds(200), waitTimeout: TimeSpan.FromMinutes(3));
            Check.Equal("succeeded", job.Status, "status");
            Check.Equal(1L, job.MapVersion, "map version");
            Check.Equal(100.0, job.Percent, "percent");
            Check.True(progress.Count >= 2, "progress reported " + progress.Count + " times");
            Check.True(progress.Zip(progress.Skip(1), (x, y) => y.Percent >= x.Percent).All(ok => ok), "progress never goes back");
            var built = await client.GetMapAsync(mapId);
            Check.Equal(3, built.Map["objects"].Count, "objects");
            Expect<PreconditionRequiredException>(() => client.BuildMapAsync(recording, mapId), "precondition-required", "header.if-match");
            var empty = JsonValue.Parse(recording.ToString());
            foreach (var f in empty["frames"].Items) f.Set("detections", JsonValue.NewArray());
            var e = Check.ThrowsAsync(() => client.BuildMapAsync(empty, "empty-" + Run, pollInterval: TimeSpan.FromMilliseconds(200)), "nothing to build");
            Check.True(e is BuildFailedException && ((BuildFailedException)e).Job.Status == "failed", e.GetType().Name + ": " + e.Message);
            await client.DeleteMapAsync(mapId);
        }
    }

    [Test(Needs = "QUADLOC_URL")]
    public static void LiveRequestErrorsAreTypedAndNameTheField()
    {
        using (var client = Live())
        {
            var bad = Demo(); bad.Camera.Fx = -1;
            Expect<ValidationException>(() => client.LocalizeAsync("chess", bad), "validation-error", "camera.fx");
            var typo = Demo(); typo.Detections[2].Extra["sigmaa"] = 1.0;
            Expect<ValidationException>(() => client.LocalizeAsync("chess", typo), "validation-error", "detections[2].sigmaa");
            var prior = Demo();
            prior.Prior = new PosePriorIn { WorldFromCamera = new PoseIn { QuaternionWxyz = new List<double> { 2, 0, 0, 0 }, TranslationM = new List<double> { 0, 0, 0 } } };
            Expect<ValidationException>(() => client.LocalizeAsync("chess", prior), "invalid-geometry");
            var map = JsonValue.Parse("{\"map_id\":\"bad-" + Run + "\",\"name\":\"x\",\"categories\":[\"a\"],\"objects\":[{\"object_id\":\"o\",\"category\":\"b\",\"center\":[0,0,0],\"axes\":[1,1,1]}]}");
            Expect<ValidationException>(() => client.CreateMapAsync(map), "invalid-map", "objects[0].category");
            Expect<NotFoundException>(() => client.LocalizeAsync("nope-" + Run, Demo()), "map-not-found");
            Expect<ConflictException>(() => client.DeleteMapAsync("chess"), "default-map");
            Expect<NotFoundException>(() => client.GetMapAsync("chess", 999), "map-not-found");
        }
    }

    [Test(Needs = "QUADLOC_KEYED_URL")]
    public static async Task LiveKeysLimitsAndCapacity()
    {
        var rec = ReadJson("docs/examples/track_chess.json");
        using (var anonymous = Live(keyed: true))
        using (var read = Live(Environment.GetEnvironmentVariable("QUADLOC_KEY_READ"), keyed: true))
        using (var rw = Live(Environment.GetEnvironmentVariable("QUADLOC_KEY_RW"), keyed: true))
        {
            Expect<UnauthorizedException>(() => anonymous.ListMapsAsync(), "unauthorized");
            Check.True((await read.LocalizeAsync("chess", Demo())).Localized, "a read key localizes");
            var office = ReadJson("docs/examples/office_map.json");
            office.Set("map_id", "o-" + Run);
            Expect<ForbiddenException>(() => read.CreateMapAsync(office), "forbidden");
            await rw.CreateMapAsync(office);
            await rw.DeleteMapAsync("o-" + Run);
            var frames = Enumerable.Range(0, 30).Select(k => { var d = Demo(); d.FrameId = "f" + k; return d; }).ToList();
            Expect<PayloadTooLargeException>(() => rw.LocalizeBatchAsync("chess", frames), "payload-too-large");
            var session = await rw.StartSessionAsync("chess", new SessionCreate { Camera = CameraIn.FromJson(rec["camera"]) });
            try
            {
                using (var impatient = Live(Environment.GetEnvironmentVariable("QUADLOC_KEY_RW"), true, new RetryPolicy { MaxRetryAfterSeconds = 10 }))
                {
                    var e = Expect<ServiceUnavailableException>(() => impatient.StartSessionAsync("chess", new SessionCreate { Camera = CameraIn.FromJson(rec["camera"]) }), "session-capacity");
                    Check.Equal(1, e.Attempts, "not retried: Retry-After is above 10 s");
                    Check.Equal(30.0, e.RetryAfterSeconds.Value, "Retry-After");
                }
            }
            finally { await session.CloseAsync(); }
        }
    }
}
