"""QuadLoc Python SDK: a typed client of the relocalization service for AR apps.

Imports neither gtsam nor the server (``quadloc.service``, ``quadloc.factors``, ``quadloc.maps``).
``import quadloc_sdk`` needs only httpx and pydantic (the ``quadloc-sdk`` distribution in ``sdk/``);
:mod:`quadloc_sdk.overlay` (SVG drawing of a localization) is pure Python;
:mod:`quadloc_sdk.geometry` needs numpy (extra ``quadloc-sdk[geometry]``) and OpenCV for its contour
helpers (extra ``[contours]``, imported lazily). See docs/sdk.md.
"""

from quadloc_sdk.client import DEFAULT_BASE_URL, SDK_VERSION, AsyncQuadLocClient, QuadLocClient
from quadloc_sdk.errors import (
    APIError,
    ClientError,
    Conflict,
    FieldError,
    Forbidden,
    NotFound,
    PayloadTooLarge,
    PreconditionFailed,
    PreconditionRequired,
    QuadLocError,
    RateLimited,
    ServerError,
    ServiceUnavailable,
    TransportError,
    Unauthorized,
    ValidationError,
)
from quadloc_sdk.models import (
    METRICS,
    NO_REFINEMENT,
    ROBUST_KERNELS,
    Alternative,
    BatchLocalizeResponse,
    Box,
    Camera,
    Covariance,
    Detection,
    Ellipse,
    Gravity,
    Inlier,
    LocalizeOptions,
    LocalizeRequest,
    LocalizeResponse,
    MapRecord,
    MapSummary,
    MapVersion,
    Pose,
    PoseInput,
    PosePrior,
)
from quadloc_sdk.retry import RetryPolicy

__version__ = SDK_VERSION

__all__ = [
    "DEFAULT_BASE_URL",
    "METRICS",
    "NO_REFINEMENT",
    "ROBUST_KERNELS",
    "APIError",
    "Alternative",
    "AsyncQuadLocClient",
    "BatchLocalizeResponse",
    "Box",
    "Camera",
    "ClientError",
    "Conflict",
    "Covariance",
    "Detection",
    "Ellipse",
    "FieldError",
    "Forbidden",
    "Gravity",
    "Inlier",
    "LocalizeOptions",
    "LocalizeRequest",
    "LocalizeResponse",
    "MapRecord",
    "MapSummary",
    "MapVersion",
    "NotFound",
    "PayloadTooLarge",
    "Pose",
    "PoseInput",
    "PosePrior",
    "PreconditionFailed",
    "PreconditionRequired",
    "QuadLocClient",
    "QuadLocError",
    "RateLimited",
    "RetryPolicy",
    "ServerError",
    "ServiceUnavailable",
    "TransportError",
    "Unauthorized",
    "ValidationError",
]
