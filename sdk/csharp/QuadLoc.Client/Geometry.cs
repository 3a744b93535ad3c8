// Geometry helpers for Unity and .NET apps: Unity's left-handed pose, pose directions, camera
// axes, quaternion orders, matrix layouts, box / mask -> ellipse. A port of the Python SDK's
// quadloc_sdk.geometry (the reference), checked against the same test vectors
// (sdk/test-vectors/*.json).
//
// Conventions (the server's): matrices are double[4, 4] ROW-major (T[r, c]) like the wire's
// `matrix`; poses are named by direction (worldFromCamera maps camera coordinates to world
// coordinates), metres; camera axes "opencv" (+X right, +Y down, +Z forward, QuadLoc's
// default) or "opengl" (ARKit / ARCore: +Y up, -Z forward), which differ by diag(1, -1, -1)
// on the camera side; quaternions are wxyz (scalar first, w >= 0) unless named xyzw; ellipses
// have SEMI-axes in px and the angle in RADIANS from +x towards +y, canonical a >= b,
// angle in [-pi/2, pi/2); pixels from the top-left pixel corner, +y down.
using System;
using System.Collections.Generic;
using System.Linq;

namespace QuadLoc.Client
{
    /// <summary>A Unity Transform's local position (metres) and rotation (x, y, z, w).</summary>
    public struct UnityPose
    {
        public double[] Position;
        /// <summary>new Quaternion(x, y, z, w) in Unity.</summary>
        public double[] RotationXyzw;
    }

    /// <summary>Bad input to a helper; the message starts with the argument's name.</summary>
    public class GeometryException : ArgumentException
    {
        public string Field { get; private set; }
        public GeometryException(string field, string message) : base(field + ": " + message) { Field = field; }
    }

    public static class Geometry
    {
        /// <summary>Tolerance on max|R R^T - I| and |det R - 1|.</summary>
        public const double OrthonormalTolerance = 1e-6;
        /// <summary>Tolerance on ||q| - 1|.</summary>
        public const double QuaternionNormTolerance = 1e-6;

        private static readonly double[,] Flip4 = { { 1, 0, 0, 0 }, { 0, -1, 0, 0 }, { 0, 0, -1, 0 }, { 0, 0, 0, 1 } };
        /// <summary>Unity camera axes (+X right, +Y up, +Z forward) from OpenCV camera axes.</summary>
        public static readonly double[,] UnityCameraFromOpencv = { { 1, 0, 0 }, { 0, -1, 0 }, { 0, 0, 1 } };
        private static readonly double[,] UnityWorldFromMapYUp = { { 1, 0, 0 }, { 0, 1, 0 }, { 0, 0, -1 } };
        private static readonly double[,] UnityWorldFromMapZUp = { { 1, 0, 0 }, { 0, 0, 1 }, { 0, 1, 0 } };

        // ----------------------------------------------------------------------- wire <-> arrays

        /// <summary>A row-major list of rows (the wire's `matrix`) as double[n, m].</summary>
        public static double[,] ToArray(IList<List<double>> rows)
        {
            if (rows == null || rows.Count == 0) throw new GeometryException("matrix", "expected rows of numbers");
            int n = rows.Count, m = rows[0].Count;
            var a = new double[n, m];
            for (int r = 0; r < n; r++)
            {
                if (rows[r].Count != m) throw new GeometryException("matrix", "rows of different lengths");
                for (int c = 0; c < m; c++) a[r, c] = rows[r][c];
            }
            return a;
        }

        /// <summary>double[n, m] as the wire's list of rows.</summary>
        public static List<List<double>> ToRows(double[,] a)
        {
            var rows = new List<List<double>>();
            for (int r = 0; r < a.GetLength(0); r++)
            {
                var row = new List<double>();
                for (int c = 0; c < a.GetLength(1); c++) row.Add(a[r, c]);
                rows.Add(row);
            }
            return rows;
        }

        /// <summary>The 4x4 pose of an answer's `world_from_camera` / `world_from_odom`.</summary>
        public static double[,] Matrix(this PoseOut pose) { return CheckPose("pose.matrix", ToArray(pose.Matrix)); }

        /// <summary>A pose to send (prior, odometry) as its row-major matrix.</summary>
        public static PoseIn PoseInput(double[,] pose) { return new PoseIn { Matrix = ToRows(CheckPose("pose", pose)) }; }

        // ----------------------------------------------------------------------- matrices

        public static double[,] MatMul(double[,] a, double[,] b)
        {
            int n = a.GetLength(0), k = a.GetLength(1), m = b.GetLength(1);
            if (b.GetLength(0) != k) throw new GeometryException("b", "shapes do not match");
            var o = new double[n, m];
            for (int r = 0; r < n; r++)
                for (int c = 0; c < m; c++)
                {
                    double s = 0;
                    for (int i = 0; i < k; i++) s += a[r, i] * b[i, c];
                    o[r, c] = s;
                }
            return o;
        }

        /// <summary>T applied to the point p (metres).</summary>
        public static double[] TransformPoint(double[,] T, double[] p)
        {
            return new[] { 0, 1, 2 }.Select(r => T[r, 0] * p[0] + T[r, 1] * p[1] + T[r, 2] * p[2] + T[r, 3]).ToArray();
        }

        /// <summary>Validates a rigid 4x4 pose (finite, last row [0, 0, 0, 1], proper rotation); returns a copy.</summary>
        public static double[,] CheckPose(string field, double[,] pose)
        {
            if (pose == null || pose.GetLength(0) != 4 || pose.GetLength(1) != 4) throw new GeometryException(field, "expected a 4x4 matrix");
            var T = (double[,])pose.Clone();
            foreach (var v in T) if (double.IsNaN(v) || double.IsInfinity(v)) throw new GeometryException(field, "contains NaN or infinite values");
            double[] last = { 0, 0, 0, 1 };
            for (int c = 0; c < 4; c++) if (Math.Abs(T[3, c] - last[c]) > 1e-9) throw new GeometryException(field, "last row must be [0, 0, 0, 1]");
            CheckRotation(field, Block3(T));
            return T;
        }

        private static double[,] Block3(double[,] T)
        {
            var R = new double[3, 3];
            for (int r = 0; r < 3; r++) for (int c = 0; c < 3; c++) R[r, c] = T[r, c];
            return R;
        }

        private static void CheckRotation(string field, double[,] R)
        {
            double err = 0;
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++)
                {
                    double s = 0;
                    for (int k = 0; k < 3; k++) s += R[i, k] * R[j, k];
                    err = Math.Max(err, Math.Abs(s - (i == j ? 1 : 0)));
                }
            double det = R[0, 0] * (R[1, 1] * R[2, 2] - R[1, 2] * R[2, 1]) - R[0, 1] * (R[1, 0] * R[2, 2] - R[1, 2] * R[2, 0])
                       + R[0, 2] * (R[1, 0] * R[2, 1] - R[1, 1] * R[2, 0]);
            if (err > OrthonormalTolerance || Math.Abs(det - 1) > OrthonormalTolerance)
                throw new GeometryException(field, "rotation block is not a proper rotation (max|R R^T - I| = " + err.ToString("G3") + ")");
        }

        /// <summary>bFromA from a rigid aFromB, using R^T.</summary>
        public static double[,] InvertPose(double[,] aFromB)
        {
            var T = CheckPose("pose", aFromB);
            var o = new double[4, 4];
            for (int r = 0; r < 3; r++) for (int c = 0; c < 3; c++) o[r, c] = T[c, r];
            for (int r = 0; r < 3; r++) o[r, 3] = -(o[r, 0] * T[0, 3] + o[r, 1] * T[1, 3] + o[r, 2] * T[2, 3]);
            o[3, 3] = 1;
            return o;
        }

        /// <summary>cameraFromWorld (OpenCV [R | t]) from worldFromCamera.</summary>
        public static double[,] ToCameraFromWorld(double[,] worldFromCamera) { return InvertPose(worldFromCamera); }

        /// <summary>worldFromCamera from cameraFromWorld.</summary>
        public static double[,] ToWorldFromCamera(double[,] cameraFromWorld) { return InvertPose(cameraFromWorld); }

        /// <summary>OpenCV camera axes -> OpenGL (ARKit / ARCore): worldFromCamera * diag(1, -1, -1, 1).</summary>
        public static double[,] WorldFromCameraOpencvToOpengl(double[,] worldFromCamera)
        {
            return MatMul(CheckPose("worldFromCamera", worldFromCamera), Flip4);
        }

        /// <summary>Inverse of WorldFromCameraOpencvToOpengl (the flip is its own inverse).</summary>
        public static double[,] WorldFromCameraOpenglToOpencv(double[,] worldFromCamera)
        {
            return MatMul(CheckPose("worldFromCamera", worldFromCamera), Flip4);
        }

        /// <summary>A 6x6 body-frame covariance [omega, v] in the flipped camera axes: J C J, J = diag(1,-1,-1,1,-1,-1).</summary>
        public static double[,] CovarianceOpencvToOpengl(double[,] covariance)
        {
            if (covariance == null || covariance.GetLength(0) != 6 || covariance.GetLength(1) != 6) throw new GeometryException("covariance", "expected a 6x6 matrix");
            double[] j = { 1, -1, -1, 1, -1, -1 };
            var o = new double[6, 6];
            for (int r = 0; r < 6; r++) for (int c = 0; c < 6; c++) o[r, c] = covariance[r, c] * j[r] * j[c];
            return o;
        }

        /// <summary>Anchors the map in an AR session: sessionFromCamera * inverse(mapFromCamera), same frame, same camera axes.</summary>
        public static double[,] SessionFromMap(double[,] sessionFromCamera, double[,] mapFromCamera)
        {
            return MatMul(CheckPose("sessionFromCamera", sessionFromCamera), InvertPose(mapFromCamera));
        }

        // ----------------------------------------------------------------------- quaternions

        /// <summary>3x3 rotation of a unit quaternion (w, x, y, z).</summary>
        public static double[,] MatrixFromQuaternionWxyz(IList<double> q)
        {
            if (q == null || q.Count != 4) throw new GeometryException("quaternionWxyz", "expected 4 numbers");
            double n = Math.Sqrt(q.Sum(v => v * v));
            if (double.IsNaN(n) || Math.Abs(n - 1) > QuaternionNormTolerance) throw new GeometryException("quaternionWxyz", "must have unit norm, got |q| = " + n);
            double w = q[0] / n, x = q[1] / n, y = q[2] / n, z = q[3] / n;
            return new double[,]
            {
                { 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y) },
                { 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x) },
                { 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y) },
            };
        }

        /// <summary>Unit quaternion (w, x, y, z), w &gt;= 0, of a 3x3 rotation (Shepperd's method).</summary>
        public static double[] QuaternionWxyzFromMatrix(double[,] R)
        {
            if (R == null || R.GetLength(0) != 3 || R.GetLength(1) != 3) throw new GeometryException("rotation", "expected a 3x3 matrix");
            foreach (var v in R) if (double.IsNaN(v) || double.IsInfinity(v)) throw new GeometryException("rotation", "contains NaN or infinite values");
            CheckRotation("rotation", R);
            double d0 = R[0, 0], d1 = R[1, 1], d2 = R[2, 2];
            double[][] cand =
            {
                new[] { 1 + d0 + d1 + d2, R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1] },
                new[] { R[2, 1] - R[1, 2], 1 + d0 - d1 - d2, R[0, 1] + R[1, 0], R[0, 2] + R[2, 0] },
                new[] { R[0, 2] - R[2, 0], R[0, 1] + R[1, 0], 1 - d0 + d1 - d2, R[1, 2] + R[2, 1] },
                new[] { R[1, 0] - R[0, 1], R[0, 2] + R[2, 0], R[1, 2] + R[2, 1], 1 - d0 - d1 + d2 },
            };
            double[] pivots = { 1 + d0 + d1 + d2, 1 + d0 - d1 - d2, 1 - d0 + d1 - d2, 1 - d0 - d1 + d2 };
            int p = 0;
            for (int i = 1; i < 4; i++) if (pivots[i] > pivots[p]) p = i;
            var q = cand[p];
            double n = Math.Sqrt(q.Sum(v => v * v));
            double s = q[0] < 0 ? -1 / n : 1 / n;
            return q.Select(v => v * s).ToArray();
        }

        /// <summary>(x, y, z, w) (Unity, ARKit, ARCore) from (w, x, y, z).</summary>
        public static double[] QuaternionXyzwFromWxyz(IList<double> q) { return new[] { q[1], q[2], q[3], q[0] }; }

        /// <summary>(w, x, y, z) from (x, y, z, w).</summary>
        public static double[] QuaternionWxyzFromXyzw(IList<double> q) { return new[] { q[3], q[0], q[1], q[2] }; }

        /// <summary>4x4 pose [[R(q), t], [0, 1]] from a quaternion (w, x, y, z) and a translation (m).</summary>
        public static double[,] PoseMatrixFromQuaternionWxyz(IList<double> q, IList<double> t)
        {
            var R = MatrixFromQuaternionWxyz(q);
            if (t == null || t.Count != 3) throw new GeometryException("translation", "expected 3 numbers");
            var T = new double[4, 4];
            for (int r = 0; r < 3; r++) { for (int c = 0; c < 3; c++) T[r, c] = R[r, c]; T[r, 3] = t[r]; }
            T[3, 3] = 1;
            return T;
        }

        // ----------------------------------------------------------------------- layouts

        /// <summary>The 16 entries column after column (Unity's Matrix4x4 m00, m10, m20, m30, m01, ..., OpenGL).</summary>
        public static double[] ColumnMajorFromMatrix(double[,] M)
        {
            if (M == null || M.GetLength(0) != 4 || M.GetLength(1) != 4) throw new GeometryException("matrix", "expected a 4x4 matrix");
            var o = new double[16];
            for (int c = 0; c < 4; c++) for (int r = 0; r < 4; r++) o[c * 4 + r] = M[r, c];
            return o;
        }

        /// <summary>Row-major 4x4 from 16 numbers column after column.</summary>
        public static double[,] MatrixFromColumnMajor(IList<double> v)
        {
            if (v == null || v.Count != 16) throw new GeometryException("values", "expected 16 numbers");
            var M = new double[4, 4];
            for (int c = 0; c < 4; c++) for (int r = 0; r < 4; r++) M[r, c] = v[c * 4 + r];
            return M;
        }

        // ----------------------------------------------------------------------- Unity

        /// <summary>
        /// A QuadLoc worldFromCamera as a Unity Transform of a camera under the map's root
        /// (transform.localPosition / localRotation = new Quaternion(x, y, z, w)). Unity is
        /// left-handed, so two reflections do it: R_unity = M_w R_cv M_c, position = M_w t, with
        /// M_c = diag(1, -1, 1) and M_w mirroring Z (worldUp "y": a right-handed Y-up world such as
        /// an ARKit / ARCore session) or swapping Y and Z (worldUp "z", the default: a Z-up map such
        /// as the demo). A map point X then sits at M_w X in Unity: place the map's objects with the
        /// same M_w (<see cref="UnityPointFromMap"/>). <paramref name="convention"/>: the camera axes
        /// of the given pose. Same numbers as the Python SDK's unity_pose_from_world_from_camera.
        /// </summary>
        public static UnityPose UnityPoseFromWorldFromCamera(double[,] worldFromCamera, string convention = "opencv", string worldUp = "z")
        {
            var Mw = UnityWorldFromMap(worldUp);
            if (convention != "opencv" && convention != "opengl") throw new GeometryException("convention", "must be \"opencv\" or \"opengl\", got \"" + convention + "\"");
            var T = CheckPose("worldFromCamera", worldFromCamera);
            if (convention == "opengl") T = MatMul(T, Flip4);
            var Ru = MatMul(MatMul(Mw, Block3(T)), UnityCameraFromOpencv);
            var t = new[] { T[0, 3], T[1, 3], T[2, 3] };
            var position = new[] { 0, 1, 2 }.Select(r => Mw[r, 0] * t[0] + Mw[r, 1] * t[1] + Mw[r, 2] * t[2]).ToArray();
            return new UnityPose { Position = position, RotationXyzw = QuaternionXyzwFromWxyz(QuaternionWxyzFromMatrix(Ru)) };
        }

        /// <summary>Where the map point X (metres) sits in Unity: M_w X.</summary>
        public static double[] UnityPointFromMap(double[] x, string worldUp = "z")
        {
            var Mw = UnityWorldFromMap(worldUp);
            return new[] { 0, 1, 2 }.Select(r => Mw[r, 0] * x[0] + Mw[r, 1] * x[1] + Mw[r, 2] * x[2]).ToArray();
        }

        private static double[,] UnityWorldFromMap(string worldUp)
        {
            if (worldUp == "y") return UnityWorldFromMapYUp;
            if (worldUp == "z") return UnityWorldFromMapZUp;
            throw new GeometryException("worldUp", "must be \"y\" or \"z\", got \"" + worldUp + "\"");
        }

        // ----------------------------------------------------------------------- ellipses

        /// <summary>The same ellipse with a &gt;= b and angle (radians) in [-pi/2, pi/2).</summary>
        public static EllipseIn CanonicalEllipse(double cx, double cy, double a, double b, double angle)
        {
            if (b > a) { var t = a; a = b; b = t; angle += Math.PI / 2; }
            double m = (angle + Math.PI / 2) % Math.PI;
            if (m < 0) m += Math.PI;
            return new EllipseIn { Cx = cx, Cy = cy, A = a, B = b, Angle = m - Math.PI / 2 };
        }

        /// <summary>The axis-aligned ellipse inscribed in a box (what the server does with `box`), px.</summary>
        public static EllipseIn EllipseFromBox(double xmin, double ymin, double xmax, double ymax)
        {
            foreach (var v in new[] { xmin, ymin, xmax, ymax })
                if (double.IsNaN(v) || double.IsInfinity(v)) throw new GeometryException("box", "must be finite numbers");
            if (!(xmax > xmin)) throw new GeometryException("box.xmax", "must be > xmin (" + xmin + "), got " + xmax);
            if (!(ymax > ymin)) throw new GeometryException("box.ymax", "must be > ymin (" + ymin + "), got " + ymax);
            return CanonicalEllipse((xmin + xmax) / 2, (ymin + ymax) / 2, (xmax - xmin) / 2, (ymax - ymin) / 2, 0);
        }

        /// <summary>
        /// Moment-matched ellipse of a binary mask, row-major (pixel (row i, column j) is
        /// mask[i * width + j], non-zero = object): the same area centroid and second moments as
        /// the pixel region, each pixel a unit square centred at (j + 0.5, i + 0.5). Same result
        /// as the Python SDK's ellipse_from_mask.
        /// </summary>
        public static EllipseIn EllipseFromMask(IList<byte> mask, int width, int height)
        {
            if (width < 1 || height < 1) throw new GeometryException("mask", "width and height must be >= 1");
            if (mask == null || mask.Count != width * height) throw new GeometryException("mask", "expected width * height = " + (width * height) + " values");
            long n = 0;
            double sx = 0, sy = 0;
            for (int i = 0; i < height; i++)
                for (int j = 0; j < width; j++)
                    if (mask[i * width + j] != 0) { n++; sx += j + 0.5; sy += i + 0.5; }
            if (n == 0) throw new GeometryException("mask", "no non-zero pixel");
            double mx = sx / n, my = sy / n, sxx = 0, syy = 0, sxy = 0;
            for (int i = 0; i < height; i++)
                for (int j = 0; j < width; j++)
                    if (mask[i * width + j] != 0)
                    {
                        double dx = j + 0.5 - mx, dy = i + 0.5 - my;
                        sxx += dx * dx; syy += dy * dy; sxy += dx * dy;
                    }
            sxx = sxx / n + 1.0 / 12; syy = syy / n + 1.0 / 12; sxy /= n;
            double half = (sxx - syy) / 2, r = Math.Sqrt(half * half + sxy * sxy), mean = (sxx + syy) / 2;
            if (!(mean - r > 0)) throw new GeometryException("mask", "the region is degenerate (zero width in some direction)");
            return CanonicalEllipse(mx, my, 2 * Math.Sqrt(mean + r), 2 * Math.Sqrt(mean - r), 0.5 * Math.Atan2(2 * sxy, sxx - syy));
        }

        /// <summary>sigma = exp(alpha / 2) for a detector's alpha = log sigma^2.</summary>
        public static double SigmaFromLogVariance(double logVariance)
        {
            if (double.IsNaN(logVariance) || double.IsInfinity(logVariance)) throw new GeometryException("logVariance", "must be finite");
            return Math.Exp(logVariance / 2);
        }

        /// <summary>alpha = 2 log sigma (sigma &gt; 0).</summary>
        public static double LogVarianceFromSigma(double sigma)
        {
            if (!(sigma > 0) || double.IsInfinity(sigma)) throw new GeometryException("sigma", "must be finite and > 0");
            return 2 * Math.Log(sigma);
        }
    }
}
