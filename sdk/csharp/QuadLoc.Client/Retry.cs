// The retry policy: exponential backoff with jitter, honouring Retry-After (the same rules as
// the Python and TypeScript SDKs, docs/sdk.md "Errors and retries"):
// - HTTP 429 and 503 are retried for every call (the server did not process the request); the
//   wait is at least the server's Retry-After (seconds or an HTTP date); a Retry-After above
//   MaxRetryAfterSeconds is not waited for: the exception is thrown at once.
// - Network failures and timeouts are retried only for idempotent calls (GETs, localization);
//   "connection refused" (nothing was sent) for every call. Creating, updating, deleting maps,
//   starting sessions, sending tracking frames and starting builds are never replayed blindly.
// - Never: any other 4xx or 5xx.
// Wait before retry k: base = min(MaxBackoffSeconds, InitialBackoffSeconds * Multiplier^(k-1)),
// drawn uniformly in [base * (1 - Jitter), base].
using System;
using System.Globalization;

namespace QuadLoc.Client
{
    /// <summary>How many times and how long the client waits before retrying. Times in seconds.</summary>
    public sealed class RetryPolicy
    {
        public int MaxAttempts { get; set; } = 4;
        public double InitialBackoffSeconds { get; set; } = 0.2;
        public double Multiplier { get; set; } = 2.0;
        public double MaxBackoffSeconds { get; set; } = 5.0;
        public double Jitter { get; set; } = 0.5;
        public bool RespectRetryAfter { get; set; } = true;
        public double MaxRetryAfterSeconds { get; set; } = 30.0;
        /// <summary>The jitter's random source in [0, 1) (seed it in tests).</summary>
        public Func<double> Random { get; set; }

        private static readonly Random Shared = new Random();

        /// <summary>Throws InvalidArgumentException naming the bad setting.</summary>
        public void Validate()
        {
            if (MaxAttempts < 1) throw new InvalidArgumentException("Retry.MaxAttempts", "must be >= 1, got " + MaxAttempts);
            if (!(InitialBackoffSeconds >= 0) || double.IsInfinity(InitialBackoffSeconds)) throw new InvalidArgumentException("Retry.InitialBackoffSeconds", "must be finite and >= 0");
            if (!(MaxBackoffSeconds >= 0) || double.IsInfinity(MaxBackoffSeconds)) throw new InvalidArgumentException("Retry.MaxBackoffSeconds", "must be finite and >= 0");
            if (!(MaxRetryAfterSeconds >= 0)) throw new InvalidArgumentException("Retry.MaxRetryAfterSeconds", "must be >= 0");
            if (!(Multiplier >= 1) || double.IsInfinity(Multiplier)) throw new InvalidArgumentException("Retry.Multiplier", "must be >= 1");
            if (!(Jitter >= 0 && Jitter <= 1)) throw new InvalidArgumentException("Retry.Jitter", "must be in [0, 1]");
        }

        /// <summary>Jittered wait (s) before retry <paramref name="retryNumber"/> (1 for the first retry).</summary>
        public double BackoffSeconds(int retryNumber)
        {
            double b = Math.Min(MaxBackoffSeconds, InitialBackoffSeconds * Math.Pow(Multiplier, retryNumber - 1));
            double r;
            if (Random != null) r = Random();
            else lock (Shared) r = Shared.NextDouble();
            return b * (1 - Jitter * r);
        }

        /// <summary>Wait (s) before retrying after <paramref name="status"/>, or null when it is not retried.</summary>
        public double? DelayForResponse(int status, string retryAfter, int retryNumber)
        {
            if (status != 429 && status != 503) return null;
            double delay = BackoffSeconds(retryNumber);
            if (RespectRetryAfter)
            {
                var advised = ParseRetryAfter(retryAfter, DateTimeOffset.UtcNow);
                if (advised.HasValue)
                {
                    if (advised.Value > MaxRetryAfterSeconds) return null;
                    delay = Math.Max(delay, advised.Value);
                }
            }
            return delay;
        }

        /// <summary>Seconds from a Retry-After value: delta-seconds or an HTTP date (relative
        /// to <paramref name="now"/>); null when absent or unparseable; never negative.</summary>
        public static double? ParseRetryAfter(string value, DateTimeOffset now)
        {
            if (string.IsNullOrWhiteSpace(value)) return null;
            value = value.Trim();
            double seconds;
            if (double.TryParse(value, NumberStyles.Float, CultureInfo.InvariantCulture, out seconds))
            {
                if (double.IsNaN(seconds) || double.IsInfinity(seconds)) return null;
                return Math.Max(0, seconds);
            }
            DateTimeOffset when;
            if (DateTimeOffset.TryParseExact(value, "r", CultureInfo.InvariantCulture, DateTimeStyles.AssumeUniversal, out when))
                return Math.Max(0, (when - now).TotalSeconds);
            return null;
        }
    }
}
