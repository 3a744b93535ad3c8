// Unity conveniences, compiled only inside Unity (UNITY_5_3_OR_NEWER is defined by the editor
// and players). Not compiled by this repository's tests (no UnityEngine here): the numbers come
// from Geometry.UnityPoseFromWorldFromCamera, which the shared test vectors check.
#if UNITY_5_3_OR_NEWER
using UnityEngine;

namespace QuadLoc.Client
{
    public static class UnityExtensions
    {
        /// <summary>Places a camera's Transform (parented to the map's root) at a QuadLoc pose.</summary>
        public static void ApplyQuadLocPose(this Transform transform, PoseOut worldFromCamera, string worldUp = "z")
        {
            var p = Geometry.UnityPoseFromWorldFromCamera(worldFromCamera.Matrix(), worldFromCamera.Convention ?? "opencv", worldUp);
            transform.localPosition = new Vector3((float)p.Position[0], (float)p.Position[1], (float)p.Position[2]);
            transform.localRotation = new Quaternion((float)p.RotationXyzw[0], (float)p.RotationXyzw[1], (float)p.RotationXyzw[2], (float)p.RotationXyzw[3]);
        }

        /// <summary>Where a map point (metres) sits under the map's root in Unity.</summary>
        public static Vector3 UnityPointFromMap(double x, double y, double z, string worldUp = "z")
        {
            var u = Geometry.UnityPointFromMap(new[] { x, y, z }, worldUp);
            return new Vector3((float)u[0], (float)u[1], (float)u[2]);
        }
    }
}
#endif
