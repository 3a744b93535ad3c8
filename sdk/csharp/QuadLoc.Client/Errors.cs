// Exceptions of the QuadLoc client. Every error the server reports is an RFC 9457 problem
// document {type, title, status, detail, instance, errors: [{field, message}]}; the client
// throws the subclass of ApiException matching its HTTP status (the Python and TypeScript
// SDKs' mapping, checked against sdk/test-vectors/problems.json: a Python / TypeScript name
// ending in "Error" ends in "Exception" here, others get "Exception" appended) and keeps the
// document. "Not localized" is NOT an error (200 with Localized == false and a Reason).
//
//   QuadLocException
//   ├── TransportException               no HTTP answer (network failure), after the retries
//   │   └── QuadLocTimeoutException      an attempt outlasted the client's Timeout
//   └── ApiException                     the server answered 4xx / 5xx
//       ├── ClientException              4xx (405, 406, 415 are plain ClientExceptions)
//       │   ├── ValidationException      400 / 422: Errors names each field
//       │   ├── UnauthorizedException    401
//       │   ├── ForbiddenException       403
//       │   ├── NotFoundException        404
//       │   ├── ConflictException        409
//       │   │   ├── PreconditionFailedException    412
//       │   │   └── PreconditionRequiredException  428
//       │   ├── PayloadTooLargeException 413
//       │   └── RateLimitedException     429 (retried; thrown when the retries run out)
//       └── ServerException              5xx
//           └── ServiceUnavailableException 503 (retried; thrown when the retries run out)
//
// Cancellation through a CancellationToken throws OperationCanceledException, as .NET does.
using System;
using System.Collections.Generic;
using System.Linq;

namespace QuadLoc.Client
{
    /// <summary>Base class of every exception of the client.</summary>
    public class QuadLocException : Exception
    {
        public QuadLocException(string message, Exception inner = null) : base(message, inner) { }
    }

    /// <summary>Bad arguments, caught before anything is sent; <see cref="Field"/> names the argument.</summary>
    public class InvalidArgumentException : QuadLocException
    {
        public string Field { get; private set; }
        public InvalidArgumentException(string field, string message) : base(field + ": " + message) { Field = field; }
    }

    /// <summary>No HTTP answer (connection failed, dropped, or timed out) after the retries allowed.</summary>
    public class TransportException : QuadLocException
    {
        public string Method { get; private set; }
        public string Url { get; private set; }
        public int Attempts { get; private set; }
        public TransportException(string message, string method, string url, int attempts, Exception inner = null)
            : base(method + " " + url + ": " + message + " (after " + attempts + " attempt(s))", inner)
        {
            Method = method; Url = url; Attempts = attempts;
        }
    }

    /// <summary>An attempt took longer than the client's (or the call's) timeout.</summary>
    public class QuadLocTimeoutException : TransportException
    {
        public QuadLocTimeoutException(string message, string method, string url, int attempts, Exception inner = null)
            : base(message, method, url, attempts, inner) { }
    }

    /// <summary>The server answered with an error status; the problem document's members are properties.</summary>
    public class ApiException : QuadLocException
    {
        public const string ProblemTypePrefix = "urn:quadloc:problem:";

        public int Status { get; private set; }
        /// <summary>The problem type, urn:quadloc:problem:&lt;slug&gt; (or about:blank).</summary>
        public string Type { get; private set; }
        /// <summary>The slug of <see cref="Type"/> (validation-error, map-not-found, ...), or null.</summary>
        public string Slug { get; private set; }
        public string Title { get; private set; }
        public string Detail { get; private set; }
        public string Instance { get; private set; }
        /// <summary>The invalid fields (detections[2].ellipse.a, query.version, header.if-match, ...).</summary>
        public List<ProblemField> Errors { get; private set; }
        /// <summary>The problem document as received (an empty object when the body was not JSON).</summary>
        public JsonValue Problem { get; private set; }
        public string Method { get; private set; }
        public string Url { get; private set; }
        /// <summary>Response headers, names lower-case.</summary>
        public IDictionary<string, string> Headers { get; private set; }
        public int Attempts { get; private set; }
        /// <summary>The raw body (e.g. a proxy's HTML error page).</summary>
        public string Text { get; private set; }

        public ApiException(int status, string method, string url, JsonValue problem, string text,
                            IDictionary<string, string> headers, int attempts)
            : base(Describe(status, method, url, problem, text))
        {
            Status = status; Method = method; Url = url; Text = text ?? "";
            Problem = problem ?? JsonValue.NewObject();
            Headers = headers ?? new Dictionary<string, string>();
            Attempts = attempts;
            Type = Member(Problem, "type") ?? "about:blank";
            Slug = Type.StartsWith(ProblemTypePrefix, StringComparison.Ordinal) ? Type.Substring(ProblemTypePrefix.Length) : null;
            Title = Member(Problem, "title") ?? ("HTTP " + status);
            Detail = Member(Problem, "detail");
            Instance = Member(Problem, "instance");
            Errors = FieldErrors(Problem);
        }

        /// <summary>The names of the invalid fields (possibly empty).</summary>
        public List<string> Fields { get { return Errors.Select(e => e.Field).ToList(); } }

        /// <summary>Seconds the server asked to wait (Retry-After), or null.</summary>
        public double? RetryAfterSeconds
        {
            get
            {
                string v;
                return Headers.TryGetValue("retry-after", out v) ? RetryPolicy.ParseRetryAfter(v, DateTimeOffset.UtcNow) : null;
            }
        }

        private static string Member(JsonValue problem, string key)
        {
            var v = problem.Kind == JsonKind.Object ? problem.Get(key) : null;
            if (v == null || v.IsNull) return null;
            return v.Kind == JsonKind.String ? v.AsString() : v.ToString();
        }

        private static List<ProblemField> FieldErrors(JsonValue problem)
        {
            var list = new List<ProblemField>();
            var errors = problem.Kind == JsonKind.Object ? problem.Get("errors") : null;
            if (errors == null || errors.Kind != JsonKind.Array) return list;
            foreach (var e in errors.Items)
            {
                if (e.Kind == JsonKind.Object)
                    list.Add(new ProblemField { Field = Member(e, "field") ?? "", Message = Member(e, "message") ?? "" });
                else
                    list.Add(new ProblemField { Field = "", Message = e.ToString() });
            }
            return list;
        }

        private static string Describe(int status, string method, string url, JsonValue problem, string text)
        {
            var p = problem ?? JsonValue.NewObject();
            var msg = status + " " + (Member(p, "title") ?? ("HTTP " + status));
            var detail = Member(p, "detail");
            if (!string.IsNullOrEmpty(detail)) msg += ": " + detail;
            var errors = FieldErrors(p);
            if (errors.Count > 0)
                msg += " [" + string.Join("; ", errors.Take(10).Select(e => e.Field + ": " + e.Message)) +
                       (errors.Count > 10 ? "; ... " + (errors.Count - 10) + " more]" : "]");
            if (problem == null && !string.IsNullOrEmpty(text)) msg += ": " + (text.Length > 200 ? text.Substring(0, 200) : text);
            return msg + " (" + method + " " + url + ")";
        }

        /// <summary>The exception for an error answer (status &gt;= 400), by status.</summary>
        public static ApiException FromResponse(int status, string method, string url, string contentType, string text,
                                                IDictionary<string, string> headers, int attempts)
        {
            JsonValue problem = null;
            if (contentType != null && contentType.Contains("json") && !string.IsNullOrEmpty(text))
            {
                try
                {
                    var parsed = JsonValue.Parse(text);
                    if (parsed.Kind == JsonKind.Object) problem = parsed;
                }
                catch (FormatException) { problem = null; }
            }
            switch (status)
            {
                case 400: case 422: return new ValidationException(status, method, url, problem, text, headers, attempts);
                case 401: return new UnauthorizedException(status, method, url, problem, text, headers, attempts);
                case 403: return new ForbiddenException(status, method, url, problem, text, headers, attempts);
                case 404: return new NotFoundException(status, method, url, problem, text, headers, attempts);
                case 409: return new ConflictException(status, method, url, problem, text, headers, attempts);
                case 412: return new PreconditionFailedException(status, method, url, problem, text, headers, attempts);
                case 413: return new PayloadTooLargeException(status, method, url, problem, text, headers, attempts);
                case 428: return new PreconditionRequiredException(status, method, url, problem, text, headers, attempts);
                case 429: return new RateLimitedException(status, method, url, problem, text, headers, attempts);
                case 503: return new ServiceUnavailableException(status, method, url, problem, text, headers, attempts);
                default:
                    return status >= 500
                        ? (ApiException)new ServerException(status, method, url, problem, text, headers, attempts)
                        : new ClientException(status, method, url, problem, text, headers, attempts);
            }
        }
    }

    /// <summary>4xx: the request is wrong; sending it again unchanged fails again (except 429).</summary>
    public class ClientException : ApiException
    {
        public ClientException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>400 / 422: the request failed validation; Errors names each field.</summary>
    public class ValidationException : ClientException
    {
        public ValidationException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>401: no API key, or an unknown one.</summary>
    public class UnauthorizedException : ClientException
    {
        public UnauthorizedException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>403: the key lacks the scope (read / write) of this call.</summary>
    public class ForbiddenException : ClientException
    {
        public ForbiddenException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>404: unknown map, map version, tracking session or build job.</summary>
    public class NotFoundException : ClientException
    {
        public NotFoundException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>409: the map id is taken, the default map cannot be deleted, or a concurrent update won.</summary>
    public class ConflictException : ClientException
    {
        public ConflictException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>412: the If-Match ETag is stale: read the map again and re-apply the change.</summary>
    public class PreconditionFailedException : ConflictException
    {
        public PreconditionFailedException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>428: updates must say which version they replace (If-Match).</summary>
    public class PreconditionRequiredException : ConflictException
    {
        public PreconditionRequiredException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>413: the body is over the server's limit (split a batch).</summary>
    public class PayloadTooLargeException : ClientException
    {
        public PayloadTooLargeException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>429: too many requests (thrown once the retries ran out).</summary>
    public class RateLimitedException : ClientException
    {
        public RateLimitedException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>5xx: the server failed; report it with Instance.</summary>
    public class ServerException : ApiException
    {
        public ServerException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }
    /// <summary>503: busy, not ready, database down, map loading (thrown once the retries ran out).</summary>
    public class ServiceUnavailableException : ServerException
    {
        public ServiceUnavailableException(int s, string m, string u, JsonValue p, string t, IDictionary<string, string> h, int a) : base(s, m, u, p, t, h, a) { }
    }

    /// <summary>A build job that ended failed (Job.Error.Reason), or did not end in time.</summary>
    public class BuildFailedException : QuadLocException
    {
        public BuildJobOut Job { get; private set; }
        public BuildFailedException(string message, BuildJobOut job) : base(message) { Job = job; }
    }
}
