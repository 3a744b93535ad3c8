"""QuadLoc Python SDK: a typed client of the relocalization service for AR apps.

Imports neither gtsam nor the server (``service``, ``factors``, ``maps``). ``import sdk`` needs
only httpx and pydantic (the ``quadloc-sdk`` distribution in ``sdk/``); :mod:`sdk.overlay`
(SVG drawing of a localization) is pure Python; :mod:`sdk.geometry` needs numpy (extra
``quadloc-sdk[geometry]``) and OpenCV for its contour helpers (extra ``[contours]``, imported
lazily). See docs/sdk.md.
"""

from sdk.client import DEFAULT_BASE_URL, SDK_VERSION, AsyncQuadLocClient, QuadLocClient
from sdk.errors import (
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
from sdk.models import (
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
from sdk.retry import RetryPolicy

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
