// The C# SDK's tests: a small runner (no test framework needed: Debian's mono compiles and
// runs it), the shared vectors (sdk/test-vectors, computed by the Python SDK), the client on a
// mocked HttpMessageHandler, and the live scenarios of the TypeScript suite against servers
// given by QUADLOC_URL / QUADLOC_KEYED_URL (skipped, saying why, without them).
// Prints one line per test and "N passed, N failed, N skipped"; exit status 1 on a failure.
using System;
using System.Collections.Generic;
using System.IO;
using System.Linq;
using System.Net;
using System.Net.Http;
using System.Reflection;
using System.Text;
using System.Threading;
using System.Threading.Tasks;
using QuadLoc.Client;

[AttributeUsage(AttributeTargets.Method)]
public sealed class TestAttribute : Attribute { public string Needs; }

public sealed class SkipException : Exception { public SkipException(string why) : base(why) { } }

public static class Check
{
    public static void True(bool condition, string what) { if (!condition) throw new Exception("expected: " + what); }
    public static void Equal<T>(T expected, T actual, string what)
    {
        if (!EqualityComparer<T>.Default.Equals(expected, actual)) throw new Exception(what + ": expected " + expected + ", got " + actual);
    }
    public static void Close(IEnumerable<double> actual, IEnumerable<double> expected, double tol, string what)
    {
        var a = actual.ToArray(); var e = expected.ToArray();
        Equal(e.Length, a.Length, what + " length");
        for (int i = 0; i < a.Length; i++)
            if (!(Math.Abs(a[i] - e[i]) <= tol)) throw new Exception(what + "[" + i + "] = " + a[i].ToString("R") + ", expected " + e[i].ToString("R") + " (tolerance " + tol + ")");
    }
    public static void AngleModPi(double actual, double expected, double tol, string what)
    {
        double d = (actual - expected) % Math.PI;
        if (d > Math.PI / 2) d -= Math.PI;
        if (d < -Math.PI / 2) d += Math.PI;
        if (!(Math.Abs(d) <= tol)) throw new Exception(what + " = " + actual + ", expected " + expected + " modulo pi");
    }
    public static TEx Throws<TEx>(Action action, string what) where TEx : Exception
    {
        try { action(); }
        catch (TEx e) { return e; }
        catch (Exception e) { throw new Exception(what + ": expected " + typeof(TEx).Name + ", got " + e.GetType().Name + ": " + e.Message); }
        throw new Exception(what + ": expected " + typeof(TEx).Name + ", nothing thrown");
    }
    public static Exception ThrowsAsync(Func<Task> action, string what)
    {
        try { action().GetAwaiter().GetResult(); }
        catch (Exception e) { return e; }
        throw new Exception(what + ": nothing thrown");
    }
}

public static partial class Tests
{
    public static string Repo = Environment.GetEnvironmentVariable("QUADLOC_REPO")
        ?? Path.GetFullPath(Path.Combine(AppDomain.CurrentDomain.BaseDirectory, "..", "..", ".."));

    public static JsonValue ReadJson(string relative) { return JsonValue.Parse(File.ReadAllText(Path.Combine(Repo, relative))); }

    public static IEnumerable<double> Flat(JsonValue v)
    {
        if (v.Kind == JsonKind.Number) return new[] { v.AsDouble() };
        return v.Items.SelectMany(Flat);
    }

    public static IEnumerable<double> Flat(double[,] a) { return a.Cast<double>(); }

    public static double[,] M(JsonValue rows) { return Geometry.ToArray(rows.AsList(r => r.AsList(x => x.AsDouble()))); }

    public static int Main(string[] args)
    {
        int passed = 0, failed = 0, skipped = 0;
        var filter = args.Length > 0 ? args[0] : null;
        foreach (var m in typeof(Tests).GetMethods(BindingFlags.Public | BindingFlags.Static)
                     .Where(m => m.GetCustomAttributes(typeof(TestAttribute), false).Length > 0)
                     .OrderBy(m => m.MetadataToken))
        {
            if (filter != null && !m.Name.Contains(filter)) continue;
            var started = DateTime.UtcNow;
            try
            {
                var needs = ((TestAttribute)m.GetCustomAttributes(typeof(TestAttribute), false)[0]).Needs;
                if (needs != null && string.IsNullOrEmpty(Environment.GetEnvironmentVariable(needs)))
                    throw new SkipException(needs + " is not set (tests/e2e/test_sdk_csharp.py starts the servers)");
                var r = m.Invoke(null, null);
                var task = r as Task;
                if (task != null) task.GetAwaiter().GetResult();
                passed++;
                Console.WriteLine("ok   " + m.Name + " (" + (int)(DateTime.UtcNow - started).TotalMilliseconds + " ms)");
            }
            catch (Exception e)
            {
                var inner = e is TargetInvocationException && e.InnerException != null ? e.InnerException : e;
                if (inner is SkipException) { skipped++; Console.WriteLine("skip " + m.Name + ": " + inner.Message); continue; }
                failed++;
                Console.WriteLine("FAIL " + m.Name + ": " + inner.GetType().Name + ": " + inner.Message);
                Console.WriteLine(inner.StackTrace);
            }
        }
        Console.WriteLine(passed + " passed, " + failed + " failed" + (skipped > 0 ? ", " + skipped + " skipped" : ""));
        return failed == 0 ? 0 : 1;
    }

    // ----------------------------------------------------------------------- vectors

    [Test]
    public static void PoseVectors()
    {
        var poses = ReadJson("sdk/test-vectors/poses.json");
        double tol = poses["tolerance"]["absolute"].AsDouble();
        Check.True(poses["quaternions"].Count >= 10, "quaternion cases");
        foreach (var c in poses["quaternions"].Items)
        {
            Check.Close(Geometry.QuaternionWxyzFromMatrix(M(c["matrix"])), Flat(c["quaternion_wxyz"]), tol, "quaternion_wxyz");
            Check.Close(Geometry.QuaternionXyzwFromWxyz(Flat(c["quaternion_wxyz"]).ToList()), Flat(c["quaternion_xyzw"]), 0, "xyzw");
            Check.Close(Geometry.QuaternionWxyzFromXyzw(Flat(c["quaternion_xyzw"]).ToList()), Flat(c["quaternion_wxyz"]), 0, "wxyz");
            Check.Close(Flat(Geometry.MatrixFromQuaternionWxyz(Flat(c["quaternion_wxyz"]).ToList())), Flat(c["matrix_from_quaternion"]), tol, "R(q)");
        }
        foreach (var c in poses["poses"].Items)
        {
            var name = c["name"].AsString();
            var T = M(c["world_from_camera"]);
            Check.Close(Flat(Geometry.ToCameraFromWorld(T)), Flat(c["camera_from_world"]), tol, name + " camera_from_world");
            Check.Close(Flat(Geometry.PoseMatrixFromQuaternionWxyz(Flat(c["quaternion_wxyz"]).ToList(), Flat(c["translation_m"]).ToList())), Flat(T), tol, name + " from q");
            Check.Close(Geometry.ColumnMajorFromMatrix(T), Flat(c["column_major"]), 0, name + " column-major");
            Check.Close(Flat(Geometry.MatrixFromColumnMajor(Flat(c["column_major"]).ToList())), Flat(T), 0, name + " from column-major");
            Check.Close(Flat(Geometry.WorldFromCameraOpencvToOpengl(T)), Flat(c["world_from_camera_opengl"]), tol, name + " opengl");
            Check.Close(Flat(Geometry.WorldFromCameraOpenglToOpencv(M(c["world_from_camera_opengl"]))), Flat(T), tol, name + " opencv");
            Check.Equal(4, c["unity"].Count, name + " unity cases");
            foreach (var u in c["unity"].Items)
            {
                var what = name + " unity " + u["convention"].AsString() + "/" + u["world_up"].AsString();
                var got = Geometry.UnityPoseFromWorldFromCamera(M(u["world_from_camera"]), u["convention"].AsString(), u["world_up"].AsString());
                Check.Close(got.Position, Flat(u["position"]), tol, what + " position");
                Check.Close(got.RotationXyzw, Flat(u["rotation_xyzw"]), tol, what + " rotation");
            }
        }
        Check.Close(Flat(Geometry.CovarianceOpencvToOpengl(M(poses["covariance"]["opencv"]))), Flat(poses["covariance"]["opengl"]), tol, "covariance");
        var s = poses["session_from_map"];
        Check.Close(Flat(Geometry.SessionFromMap(M(s["session_from_camera"]), M(s["map_from_camera"]))), Flat(s["session_from_map"]), tol, "session_from_map");
        foreach (var bad in poses["invalid_poses"].Items)
        {
            var e = Check.Throws<GeometryException>(() => Geometry.InvertPose(M(bad["matrix"])), bad["why"].AsString());
            Check.Equal("pose", e.Field, "field");
            Check.Throws<GeometryException>(() => Geometry.UnityPoseFromWorldFromCamera(M(bad["matrix"])), bad["why"].AsString());
        }
    }

    static void AssertEllipse(EllipseIn got, JsonValue expected, double tol, string what)
    {
        Check.Close(new[] { got.Cx, got.Cy, got.A, got.B }, new[] { expected["cx"].AsDouble(), expected["cy"].AsDouble(), expected["a"].AsDouble(), expected["b"].AsDouble() }, tol, what);
        Check.True(got.Angle >= -Math.PI / 2 && got.Angle < Math.PI / 2, what + " canonical angle");
        Check.AngleModPi(got.Angle.Value, expected["angle"].AsDouble(), tol, what + " angle");
    }

    [Test]
    public static void EllipseVectors()
    {
        var v = ReadJson("sdk/test-vectors/ellipses.json");
        double tol = v["tolerance"]["absolute"].AsDouble();
        foreach (var c in v["boxes"].Items)
        {
            var b = Flat(c["box"]).ToArray();
            AssertEllipse(Geometry.EllipseFromBox(b[0], b[1], b[2], b[3]), c["ellipse"], tol, "box");
        }
        Check.Equal("box.xmax", Check.Throws<GeometryException>(() => Geometry.EllipseFromBox(10, 10, 5, 20), "inverted box").Field, "field");
        foreach (var c in v["canonical"].Items)
        {
            var i = Flat(c["input"]).ToArray();
            AssertEllipse(Geometry.CanonicalEllipse(i[0], i[1], i[2], i[3], i[4]), c["ellipse"], tol, "canonical");
        }
        Check.True(v["masks"].Count >= 4, "mask cases");
        foreach (var m in v["masks"].Items)
        {
            int w = (int)m["width"].AsLong(), h = (int)m["height"].AsLong();
            var data = new byte[w * h];
            foreach (var run in m["runs"].Items)
            {
                int row = (int)run[0].AsLong();
                for (int j = (int)run[1].AsLong(); j < run[2].AsLong(); j++) data[row * w + j] = 1;
            }
            AssertEllipse(Geometry.EllipseFromMask(data, w, h), m["ellipse"], tol, "mask " + m["name"].AsString());
        }
        Check.Throws<GeometryException>(() => Geometry.EllipseFromMask(new byte[4], 2, 2), "empty mask");
        foreach (var c in v["log_variance"].Items)
        {
            Check.Close(new[] { Geometry.SigmaFromLogVariance(c["log_variance"].AsDouble()) }, new[] { c["sigma"].AsDouble() }, tol, "sigma");
            Check.Close(new[] { Geometry.LogVarianceFromSigma(c["sigma"].AsDouble()) }, new[] { c["log_variance"].AsDouble() }, tol, "log_variance");
        }
    }

    // ----------------------------------------------------------------------- JSON and models

    [Test]
    public static void JsonRoundTripsAndRefusesNonFiniteNumbersNamingThePath()
    {
        var text = "{\"a\":[1,2.5,-3e-7,1e+300],\"s\":\"\\u00e9\\n\\\"x\\\"\",\"n\":null,\"t\":true,\"o\":{}}";
        var v = JsonValue.Parse(text);
        Check.Equal(2.5, v["a"][1].AsDouble(), "number");
        Check.Equal("\u00e9\n\"x\"", v["s"].AsString(), "string");
        var again = JsonValue.Parse(v.ToString());
        Check.Equal(v.ToString(), again.ToString(), "round trip");
        Check.Equal(-3e-7, again["a"][2].AsDouble(), "exact double");
        Check.Throws<FormatException>(() => JsonValue.Parse("{\"a\": NaN}"), "NaN literal");
        Check.Throws<FormatException>(() => JsonValue.Parse("[1,]"), "trailing comma");
        var demo = LocalizeRequest.FromJson(ReadJson("docs/examples/localize_chess.json"));
        demo.Detections[2].Ellipse.A = double.NaN;
        var e = Check.Throws<ArgumentException>(() => demo.ToJson().ToJson("request"), "NaN");
        Check.True(e.Message.StartsWith("request.detections[2].ellipse.a:"), e.Message);
    }

    [Test]
    public static void GeneratedModelsReadAndWriteTheWireFormat()
    {
        var json = ReadJson("docs/examples/localize_chess.json");
        var request = LocalizeRequest.FromJson(json);
        Check.Equal(532.57, request.Camera.Fx, "camera.fx");
        Check.Equal(640L, request.Camera.Width, "camera.width");
        Check.True(request.Detections.Count >= 6, "detections");
        // what is read is written back unchanged (members this SDK does not know included)
        json.Set("future_field", new JsonValue("kept"));
        var back = JsonValue.Parse(LocalizeRequest.FromJson(json).ToJson().ToString());
        Check.Equal("kept", back["future_field"].AsString(), "extra member");
        Check.Equal(json["detections"].ToString(), back["detections"].ToString(), "detections round trip");
        Check.True(WireSchemas.Names.Contains("LocalizeResponse") && WireSchemas.OpenApiSha256.Length == 64, "schema list");
    }

    // ----------------------------------------------------------------------- the client, mocked

    public sealed class MockHandler : HttpMessageHandler
    {
        public readonly List<HttpRequestMessage> Requests = new List<HttpRequestMessage>();
        public readonly List<string> Bodies = new List<string>();
        private readonly Func<HttpRequestMessage, int, CancellationToken, Task<HttpResponseMessage>> _answer;
        public MockHandler(Func<HttpRequestMessage, int, CancellationToken, Task<HttpResponseMessage>> answer) { _answer = answer; }
        public MockHandler(Func<HttpRequestMessage, int, HttpResponseMessage> answer) { _answer = (r, n, ct) => Task.FromResult(answer(r, n)); }
        protected override async Task<HttpResponseMessage> SendAsync(HttpRequestMessage request, CancellationToken ct)
        {
            Requests.Add(request);
            Bodies.Add(request.Content == null ? null : await request.Content.ReadAsStringAsync());
            return await _answer(request, Requests.Count, ct);
        }
    }

    public static HttpResponseMessage Problem(int status, string slug, string retryAfter = null)
    {
        var body = "{\"type\":\"urn:quadloc:problem:" + slug + "\",\"title\":\"" + slug + "\",\"status\":" + status +
                   ",\"detail\":\"it happened\",\"instance\":\"/v1/x\",\"errors\":[{\"field\":\"camera.fx\",\"message\":\"bad\"}]}";
        var r = new HttpResponseMessage((HttpStatusCode)status) { Content = new StringContent(body, Encoding.UTF8, "application/problem+json") };
        if (retryAfter != null) r.Headers.TryAddWithoutValidation("Retry-After", retryAfter);
        return r;
    }

    public static HttpResponseMessage Ok(string body)
    {
        return new HttpResponseMessage(HttpStatusCode.OK) { Content = new StringContent(body, Encoding.UTF8, "application/json") };
    }

    public static QuadLocClient Mocked(MockHandler handler, int maxAttempts = 4, double timeoutSeconds = 30)
    {
        return new QuadLocClient(new QuadLocClientOptions
        {
            BaseUrl = "http://quadloc.test", Handler = handler, Timeout = TimeSpan.FromSeconds(timeoutSeconds),
            Retry = new RetryPolicy { MaxAttempts = maxAttempts, InitialBackoffSeconds = 0.001, MaxBackoffSeconds = 0.002 },
        });
    }

    public static LocalizeRequest Demo() { return LocalizeRequest.FromJson(ReadJson("docs/examples/localize_chess.json")); }

    [Test]
    public static void EveryDocumentedProblemMapsToTheExceptionOfTheSharedVectors()
    {
        var problems = ReadJson("sdk/test-vectors/problems.json")["problems"].Items;
        Check.True(problems.Count >= 20, "problem types");
        foreach (var p in problems)
        {
            int status = (int)p["status"].AsLong();
            var slug = p["slug"].AsString();
            var python = p["error"].AsString();
            var expected = python.EndsWith("Error") ? python.Substring(0, python.Length - 5) + "Exception" : python + "Exception";
            using (var client = Mocked(new MockHandler((r, n) => Problem(status, slug, "0")), maxAttempts: 1))
            {
                var e = Check.ThrowsAsync(() => client.LocalizeAsync("chess", Demo()), slug) as ApiException;
                Check.True(e != null, slug + " gives an ApiException");
                Check.Equal(expected, e.GetType().Name, slug + " (" + status + ")");
                Check.Equal(status, e.Status, "status");
                Check.Equal(slug, e.Slug, "slug");
                Check.Equal("urn:quadloc:problem:" + slug, e.Type, "type");
                Check.Equal("camera.fx", e.Fields.Single(), "field");
                Check.Equal("/v1/x", e.Instance, "instance");
                Check.True(e.Message.Contains("camera.fx: bad"), e.Message);
            }
        }
        Check.True(new PreconditionFailedException(412, "PUT", "u", null, "", null, 1) is ConflictException, "412 is a Conflict");
        Check.True(new ServiceUnavailableException(503, "GET", "u", null, "", null, 1) is ServerException, "503 is a ServerError");
    }

    [Test]
    public static void RetriesHonourRetryAfterAndStopWhereTheyMust()
    {
        var h = new MockHandler((r, n) => n == 1 ? Problem(429, "rate-limited", "0.3") : n == 2 ? Problem(503, "busy", "0") : Ok("{\"maps\":[]}"));
        using (var client = Mocked(h))
        {
            var t0 = DateTime.UtcNow;
            Check.Equal(0, client.ListMapsAsync().GetAwaiter().GetResult().Count, "maps");
            Check.Equal(3, h.Requests.Count, "attempts");
            Check.True((DateTime.UtcNow - t0).TotalMilliseconds >= 290, "waited Retry-After");
        }
        var busy = new MockHandler((r, n) => Problem(503, "busy", "0"));
        using (var client = Mocked(busy, maxAttempts: 3))
        {
            var e = (ServiceUnavailableException)Check.ThrowsAsync(() => client.LocalizeAsync("chess", Demo()), "busy");
            Check.Equal(3, e.Attempts, "attempts");
            Check.Equal(0.0, e.RetryAfterSeconds.Value, "retry after");
        }
        var later = new MockHandler((r, n) => Problem(429, "rate-limited", "120"));
        using (var client = Mocked(later))
        {
            var e = (RateLimitedException)Check.ThrowsAsync(() => client.ListMapsAsync(), "too long");
            Check.Equal(1, later.Requests.Count, "not waited for");
            Check.Equal(120.0, e.RetryAfterSeconds.Value, "retry after");
        }
        foreach (var status in new[] { 400, 404, 409, 422, 500 })
        {
            var once = new MockHandler((r, n) => Problem(status, "x"));
            using (var client = Mocked(once)) Check.ThrowsAsync(() => client.ListMapsAsync(), "status " + status);
            Check.Equal(1, once.Requests.Count, "status " + status + " not retried");
        }
        Check.Equal(10.0, RetryPolicy.ParseRetryAfter("Wed, 21 Oct 2015 07:28:10 GMT", new DateTimeOffset(2015, 10, 21, 7, 28, 0, TimeSpan.Zero)).Value, "HTTP date");
        Check.True(RetryPolicy.ParseRetryAfter("soon", DateTimeOffset.UtcNow) == null, "unparseable");
    }

    [Test]
    public static void NetworkFailuresTimeoutsAndCancellation()
    {
        var failing = new MockHandler((r, n) => { throw new HttpRequestException("connection reset"); });
        using (var client = Mocked(failing))
        {
            var e = (TransportException)Check.ThrowsAsync(() => client.LocalizeAsync("chess", Demo()), "idempotent");
            Check.Equal(4, e.Attempts, "localize retried");
        }
        var failingWrite = new MockHandler((r, n) => { throw new HttpRequestException("connection reset"); });
        using (var client = Mocked(failingWrite))
        {
            Check.ThrowsAsync(() => client.DeleteMapAsync("x"), "write");
            Check.Equal(1, failingWrite.Requests.Count, "a delete is not replayed");
        }
        Func<HttpRequestMessage, int, CancellationToken, Task<HttpResponseMessage>> hang = async (r, n, ct) =>
        {
            await Task.Delay(TimeSpan.FromSeconds(30), ct);
            return Ok("{}");
        };
        var hanging = new MockHandler(hang);
        using (var client = Mocked(hanging, maxAttempts: 2, timeoutSeconds: 0.05))
        {
            var e = Check.ThrowsAsync(() => client.LocalizeAsync("chess", Demo()), "timeout");
            Check.True(e is QuadLocTimeoutException && ((QuadLocTimeoutException)e).Attempts == 2, e.GetType().Name + ": " + e.Message);
        }
        using (var client = Mocked(new MockHandler(hang)))
        using (var cts = new CancellationTokenSource(TimeSpan.FromMilliseconds(50)))
        {
            var t0 = DateTime.UtcNow;
            var e = Check.ThrowsAsync(() => client.LocalizeAsync("chess", Demo(), null, cts.Token), "cancel");
            Check.True(e is OperationCanceledException, e.GetType().Name);
            Check.True((DateTime.UtcNow - t0).TotalSeconds < 5, "cancelled promptly");
        }
    }

    [Test]
    public static void RequestsCarryTheKeyTheVersionAndTheETag()
    {
        var h = new MockHandler((r, n) => r.RequestUri.AbsolutePath.EndsWith("/localize")
            ? Ok("{\"localized\":false,\"reason\":\"too_few_detections\",\"map_id\":\"chess\",\"map_version\":1,\"confidence\":0,\"inliers\":[],\"alternatives\":[]}")
            : OkWithEtag());
        using (var client = new QuadLocClient(new QuadLocClientOptions { BaseUrl = "http://quadloc.test/", ApiKey = "k-123", Handler = h }))
        {
            var answer = client.LocalizeAsync("chess", Demo(), 1).GetAwaiter().GetResult();
            Check.Equal(false, answer.Localized, "localized");
            Check.Equal("http://quadloc.test/v1/maps/chess/localize?version=1", h.Requests[0].RequestUri.ToString(), "url");
            Check.Equal("Bearer k-123", string.Join("", h.Requests[0].Headers.GetValues("Authorization")), "key");
            Check.Equal(ReadJson("docs/examples/localize_chess.json").ToString(), JsonValue.Parse(h.Bodies[0]).ToString(), "body");
            var rec = client.UpdateMapAsync("my map/1", JsonValue.NewObject(), "h").GetAwaiter().GetResult();
            Check.Equal("\"h\"", rec.ETag, "etag");
            Check.Equal("/v1/maps/my%20map%2F1", h.Requests[1].RequestUri.AbsolutePath.Replace("%2f", "%2F"), "escaped id");
            Check.Equal("\"h\"", string.Join("", h.Requests[1].Headers.GetValues("If-Match")), "if-match");
            var bad = Demo();
            bad.Detections[2].Ellipse.A = double.NaN;
            var e = Check.ThrowsAsync(() => client.LocalizeAsync("chess", bad), "NaN") as InvalidArgumentException;
            Check.Equal("request.detections[2].ellipse.a", e.Field, "field");
            Check.Equal(2, h.Requests.Count, "nothing sent");
        }
        Check.Throws<InvalidArgumentException>(() => new QuadLocClient(new QuadLocClientOptions { BaseUrl = "ftp://x" }), "base url");
    }

    static HttpResponseMessage OkWithEtag()
    {
        var r = Ok("{\"map_id\":\"m\",\"version\":2,\"content_hash\":\"h\",\"map\":{}}");
        r.Headers.TryAddWithoutValidation("ETag", "\"h\"");
        return r;
    }
}
