"""Simulated object detections: what a fine-tuned ellipse detector would report for one frame.

Given a map (``SceneMap`` or ``CompiledMap``), a :class:`~quadloc.factors.camera.Camera` and the
true ``world_from_camera`` pose (4x4, OpenCV camera axes), :func:`simulate_frame` returns the
detections of one image. The model (documented with its numbers in ``docs/simulation.md``):

1. **Projection.** Every map object whose ellipsoid lies entirely in front of the camera
   (depth margin > ``min_depth_m``) is projected exactly, ``C* = P Q* P^T``.
2. **Visibility.** ``n_visibility_samples`` sunflower points fill the projected ellipse
   uniformly. A point is hidden when it is outside the image ``[0, W] x [0, H]``, inside the
   (``occluder_shrink``-scaled) projection of a *nearer* map object, or inside a random
   rectangular occluder (probability ``occluder_probability`` per object). The detection is
   the **moment-matched ellipse of the visible points** (mean, and ``4 x`` covariance, which is
   exact for a uniform ellipse), so a truncated or occluded object is detected as the ellipse
   of its visible part (paper figure 2), not its full projection. With
   ``visible_ellipse="box"`` it is instead the axis-aligned ellipse inscribed in the bounding
   box of the visible points (what box-based detectors mostly report). Objects with a visible
   fraction < ``min_visible_fraction`` or a visible area < ``min_visible_area_px`` are not
   detected. A fully visible object keeps its exact projection.
3. **Detector noise** (per detection, applied to the visible ellipse): a difficulty factor
   ``k ~ LogNormal(0, difficulty_log_std)``; centre ``+ N(0, (k center_noise sqrt(a b))^2)``
   px per axis; semi-axes ``x exp(N(0, (k axis_log_noise)^2))``; angle
   ``+ N(0, (k angle_noise_rad)^2)``.
4. **Predicted sigma** (the paper's network predicts ``sigma``, trained with the level-set
   distance): ``sigma = max(d, sigma_floor) * exp(N(0, sigma_log_noise^2))`` where ``d`` is the
   level-set distance between the detection and the object's *true full* projection
   (:func:`level_set_distance`), so sigma correlates with each detection's true error.
5. **Misses and outliers.** Each detection is missed with probability ``miss_probability``,
   but at least ``min_detections`` (the largest) are kept when that many are visible. Optional
   outliers: a detection's label is replaced by another category with probability
   ``wrong_label_probability``; ``Poisson(spurious_rate)`` spurious ellipses with random labels
   are added, each with a sigma drawn like a true detection's (one of the frame's true sigmas
   times ``exp(N(0, sigma_log_noise^2))``): sigma carries no hint of which ones are spurious.

Everything is driven by one ``numpy.random.Generator`` (or an integer seed): same seed, same
frame. ``SimulationConfig.exact()`` gives the exact projections of all objects overlapping the
image (no noise, truncation, occlusion, misses or outliers).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from quadloc.factors.camera import Camera, ellipsoid_depth_margins, project_ellipsoids_dual
from quadloc.factors.conics import Ellipse, level_values, params_from_dual_conics
from quadloc.factors.rotations import invert_pose, so3_exp
from quadloc.maps.compiled import CompiledMap, compile_map
from quadloc.maps.model import SceneMap
from quadloc.service.localization.scoring import sunflower_disk
from quadloc.service.localization.types import Detection

__all__ = [
    "SimulatedFrame",
    "SimulationConfig",
    "level_set_distance",
    "moment_ellipse",
    "simulate_frame",
    "simulate_frames",
    "simulate_gravity",
]


def moment_ellipse(points: np.ndarray) -> Ellipse:
    """The ellipse with the same mean and covariance as a uniform distribution over it.

    For a uniform ellipse with semi-axes ``a, b`` the covariance is ``R diag(a^2, b^2) R^T / 4``,
    so the ellipse is ``mu = mean(points)``, ``Sigma = 4 cov(points)``. ``points`` (M, 2) px.
    """
    p = np.asarray(points, dtype=float)
    mu = p.mean(axis=0)
    d = p - mu
    cov = d.T @ d / len(p)
    return Ellipse.from_gaussian(mu, 4.0 * cov)


def level_set_distance(detection: Ellipse, truth: Ellipse, n: int = 64) -> float:
    """Mean squared level-set difference ``mean_i (Phi_det(x_i) - Phi_true(x_i))^2`` (unitless).

    ``x_i`` are ``n`` sunflower points over the true ellipse scaled by 1.5 (so the region just
    outside the contour counts too). 0 for identical ellipses; used for the simulated sigma.
    """
    pts = sunflower_disk(n) * 1.5
    x = pts * [truth.a, truth.b] @ truth.rotation.T + truth.center
    phi = level_values(np.stack([detection.params(), truth.params()]), np.stack([x, x]))
    return float(np.mean((phi[0] - phi[1]) ** 2))


@dataclass(frozen=True)
class SimulationConfig:
    """Parameters of the detection model (defaults: a fine-tuned detector, see module doc).

    Units: ``center_noise`` is a fraction of ``sqrt(a b)`` (px per px); ``axis_log_noise`` is the
    std of ``log`` of the semi-axis scale; ``angle_noise_rad`` radians; probabilities in [0, 1].
    """

    center_noise: float = 0.04
    axis_log_noise: float = 0.06
    angle_noise_rad: float = math.radians(4.0)
    difficulty_log_std: float = 0.5
    sigma_log_noise: float = 0.3
    sigma_floor: float = 1e-4
    predict_sigma: bool = True
    clip_to_image: bool = True
    occlusion_by_objects: bool = True
    occluder_shrink: float = 0.8
    occluder_probability: float = 0.15
    occluder_coverage: tuple[float, float] = (0.2, 0.5)
    min_visible_fraction: float = 0.3
    min_visible_area_px: float = 150.0
    min_depth_m: float = 0.05
    miss_probability: float = 0.1
    min_detections: int = 2
    wrong_label_probability: float = 0.0
    spurious_rate: float = 0.0
    n_visibility_samples: int = 600
    #: the ellipse of a partly visible object: ``"moment"`` (moment-matched to the visible
    #: points) or ``"box"`` (inscribed in their axis-aligned bounding box)
    visible_ellipse: str = "moment"

    def __post_init__(self) -> None:
        for name in ("center_noise", "axis_log_noise", "angle_noise_rad", "difficulty_log_std",
                     "sigma_log_noise", "spurious_rate", "min_visible_area_px"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"SimulationConfig.{name} must be finite and >= 0, got {v}")
        for name in ("occluder_probability", "min_visible_fraction", "miss_probability",
                     "wrong_label_probability", "occluder_shrink"):
            v = getattr(self, name)
            if not (0.0 <= v <= 1.0):
                raise ValueError(f"SimulationConfig.{name} must be in [0, 1], got {v}")
        if self.visible_ellipse not in ("moment", "box"):
            raise ValueError(f"SimulationConfig.visible_ellipse must be 'moment' or 'box', got "
                             f"{self.visible_ellipse!r}")
        if self.n_visibility_samples < 50:
            raise ValueError("SimulationConfig.n_visibility_samples must be >= 50")

    @classmethod
    def exact(cls, clip_to_image: bool = False) -> SimulationConfig:
        """Noise-free detections: the exact projection of every object that is in front of the
        camera and overlaps the image (no truncation unless ``clip_to_image``, no occlusion,
        misses or outliers)."""
        return cls(center_noise=0.0, axis_log_noise=0.0, angle_noise_rad=0.0,
                   difficulty_log_std=0.0, sigma_log_noise=0.0, predict_sigma=False,
                   clip_to_image=clip_to_image, occlusion_by_objects=False,
                   occluder_probability=0.0, miss_probability=0.0, min_visible_fraction=0.0,
                   min_visible_area_px=1.0)

    def with_(self, **changes: object) -> SimulationConfig:
        """A copy with some fields changed."""
        return replace(self, **changes)


@dataclass(frozen=True, eq=False)
class SimulatedFrame:
    """One simulated image.

    Attributes:
        detections: the detections, in random order.
        object_ids: the true map object id of each detection (``None`` for spurious ones).
        true_labels: the object's true category (``None`` for spurious ones).
        full_projections: the exact projection of the true object (``None`` for spurious).
        visible_fraction: fraction of the projected ellipse visible (1 for spurious ones).
        world_from_camera: the true pose used (4x4).
    """

    detections: tuple[Detection, ...]
    object_ids: tuple[str | None, ...]
    true_labels: tuple[str | None, ...]
    full_projections: tuple[Ellipse | None, ...]
    visible_fraction: np.ndarray
    world_from_camera: np.ndarray = field(repr=False)

    def __len__(self) -> int:
        return len(self.detections)


def _valid_projections(
    compiled: CompiledMap, camera: Camera, camera_from_world: np.ndarray, min_depth: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices of objects projecting to ellipses, their params (K, 5) and centre depths (K,)."""
    margins = ellipsoid_depth_margins(camera_from_world, compiled.centers,
                                      compiled.shape_matrices)
    idx = np.flatnonzero(margins > min_depth)
    if idx.size == 0:
        return idx, np.zeros((0, 5)), np.zeros(0)
    duals = project_ellipsoids_dual(camera, camera_from_world, compiled.dual_quadrics[idx])
    params = params_from_dual_conics(duals)
    depth = compiled.centers[idx] @ camera_from_world[2, :3] + camera_from_world[2, 3]
    return idx, params, depth


def _inside(params: np.ndarray, points: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Mask (M,) of points (M, 2) inside an ellipse (5,) scaled by ``scale`` about its centre."""
    return level_values(params[None], points[None])[0] <= scale * scale


def simulate_frame(
    scene_map: SceneMap | CompiledMap,
    camera: Camera,
    world_from_camera: np.ndarray,
    rng: np.random.Generator | int | None = None,
    config: SimulationConfig | None = None,
) -> SimulatedFrame:
    """Simulate the detections of one image (see the module docstring for the model).

    Args:
        scene_map: the map (world frame, metres).
        camera: intrinsics and image size (px).
        world_from_camera: true 4x4 camera pose in the map (OpenCV camera axes).
        rng: a ``numpy.random.Generator`` or an integer seed (deterministic).
        config: the detection model; default :class:`SimulationConfig`.
    """
    cfg = config or SimulationConfig()
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    compiled = scene_map if isinstance(scene_map, CompiledMap) else compile_map(scene_map)
    T_wc = np.asarray(world_from_camera, dtype=float)
    if T_wc.shape != (4, 4) or not np.all(np.isfinite(T_wc)):
        raise ValueError("world_from_camera must be a finite 4x4 matrix")
    T_cw = invert_pose(T_wc)
    idx, params, depth = _valid_projections(compiled, camera, T_cw, cfg.min_depth_m)
    disk = sunflower_disk(cfg.n_visibility_samples)
    W, H = camera.width, camera.height

    dets: list[Detection] = []
    ids: list[str | None] = []
    labels: list[str | None] = []
    fulls: list[Ellipse | None] = []
    fractions: list[float] = []
    areas: list[float] = []
    for k, obj in enumerate(idx):
        p = params[k]
        full = Ellipse(*p)
        pts = disk * [p[2], p[3]] @ full.rotation.T + p[:2]
        in_image = (pts[:, 0] >= 0) & (pts[:, 0] <= W) & (pts[:, 1] >= 0) & (pts[:, 1] <= H)
        if not in_image.any():
            continue
        visible = in_image.copy() if cfg.clip_to_image else np.ones(len(pts), dtype=bool)
        if cfg.occlusion_by_objects:
            for j in np.flatnonzero(depth < depth[k]):
                visible &= ~_inside(params[j], pts, cfg.occluder_shrink)
        if cfg.occluder_probability > 0 and gen.random() < cfg.occluder_probability:
            # A random box covering a fraction of the ellipse's bounding box from one side.
            box = full.bbox()
            cover = gen.uniform(*cfg.occluder_coverage)
            side = gen.integers(4)
            axis = side % 2
            lo, hi = box[axis], box[axis + 2]
            cut = lo + cover * (hi - lo) if side < 2 else hi - cover * (hi - lo)
            visible &= (pts[:, axis] > cut) if side < 2 else (pts[:, axis] < cut)
        frac = float(visible.mean())
        area = frac * full.area
        if frac < max(cfg.min_visible_fraction, 1e-9) or area < cfg.min_visible_area_px:
            continue
        if frac == 1.0:
            seen = full
        else:
            try:
                seen = moment_ellipse(pts[visible]) if cfg.visible_ellipse == "moment" \
                    else Ellipse.from_bbox(*pts[visible].min(axis=0), *pts[visible].max(axis=0))
            except ValueError:  # degenerate visible set (a sliver): undetectable
                continue
        noisy = _add_noise(seen, cfg, gen)
        sigma = None
        if cfg.predict_sigma:
            d = level_set_distance(noisy, full)
            sigma = max(d, cfg.sigma_floor) * math.exp(gen.normal(0.0, cfg.sigma_log_noise))
        label = compiled.categories[obj]
        dets.append(Detection(noisy, label, sigma))
        ids.append(compiled.object_ids[obj])
        labels.append(label)
        fulls.append(full)
        fractions.append(frac)
        areas.append(area)

    # Missed detections, keeping at least min_detections (the largest) when possible.
    keep = gen.random(len(dets)) >= cfg.miss_probability
    if keep.sum() < min(cfg.min_detections, len(dets)):
        for i in np.argsort(areas)[::-1]:
            keep[i] = True
            if keep.sum() >= cfg.min_detections:
                break
    sel = np.flatnonzero(keep)
    dets = [dets[i] for i in sel]
    ids = [ids[i] for i in sel]
    labels = [labels[i] for i in sel]
    fulls = [fulls[i] for i in sel]
    fractions = [fractions[i] for i in sel]

    # Outliers.
    cats = sorted(set(compiled.categories))
    if cfg.wrong_label_probability > 0 and len(cats) > 1:
        for i, d in enumerate(dets):
            if gen.random() < cfg.wrong_label_probability:
                others = [c for c in cats if c != d.label]
                dets[i] = replace(d, label=others[int(gen.integers(len(others)))])
    n_spurious = int(gen.poisson(cfg.spurious_rate)) if cfg.spurious_rate > 0 else 0
    # A detector cannot tell its false positives: their sigma is drawn like a true
    # detection's (one of this frame's true sigmas, re-noised), so sigma weighting gets no
    # free hint about which detections are spurious.
    true_sigmas = [d.sigma for d in dets if d.sigma is not None] or [cfg.sigma_floor]
    for _ in range(n_spurious):
        a = gen.uniform(15, 80)
        e = Ellipse(gen.uniform(0, W), gen.uniform(0, H), a, a * gen.uniform(0.4, 1.0),
                    gen.uniform(-math.pi / 2, math.pi / 2))
        sigma = None
        if cfg.predict_sigma:
            sigma = float(true_sigmas[int(gen.integers(len(true_sigmas)))]
                          * math.exp(gen.normal(0.0, cfg.sigma_log_noise)))
        dets.append(Detection(e, cats[int(gen.integers(len(cats)))], sigma))
        ids.append(None)
        labels.append(None)
        fulls.append(None)
        fractions.append(1.0)

    order = gen.permutation(len(dets))
    return SimulatedFrame(
        detections=tuple(dets[i] for i in order),
        object_ids=tuple(ids[i] for i in order),
        true_labels=tuple(labels[i] for i in order),
        full_projections=tuple(fulls[i] for i in order),
        visible_fraction=np.array([fractions[i] for i in order], dtype=float),
        world_from_camera=T_wc.copy(),
    )


def _add_noise(e: Ellipse, cfg: SimulationConfig, gen: np.random.Generator) -> Ellipse:
    if cfg.center_noise == 0 and cfg.axis_log_noise == 0 and cfg.angle_noise_rad == 0:
        return e
    k = math.exp(gen.normal(0.0, cfg.difficulty_log_std)) if cfg.difficulty_log_std > 0 else 1.0
    size = math.sqrt(e.a * e.b)
    dc = gen.normal(0.0, k * cfg.center_noise * size, 2)
    s = np.exp(gen.normal(0.0, k * cfg.axis_log_noise, 2))
    da = gen.normal(0.0, k * cfg.angle_noise_rad)
    return Ellipse(e.cx + dc[0], e.cy + dc[1], e.a * s[0], e.b * s[1], e.angle + da)


def simulate_frames(
    scene_map: SceneMap | CompiledMap,
    camera: Camera,
    poses_world_from_camera: Sequence[np.ndarray],
    seed: int = 0,
    config: SimulationConfig | None = None,
) -> list[SimulatedFrame]:
    """:func:`simulate_frame` for many poses with one seeded generator (deterministic)."""
    gen = np.random.default_rng(seed)
    compiled = scene_map if isinstance(scene_map, CompiledMap) else compile_map(scene_map)
    return [simulate_frame(compiled, camera, T, gen, config) for T in poses_world_from_camera]


def simulate_gravity(world_from_camera: np.ndarray, up_world: np.ndarray, sigma_deg: float,
                     gen: np.random.Generator | int) -> np.ndarray:
    """What an IMU reports as gravity for a camera at ``world_from_camera`` (OpenCV axes): the
    true down direction in the camera, ``R^T (-up_world)``, tilted by a Gaussian angle of
    ``sigma_deg`` (degrees) along each of the two axes perpendicular to it. Returns (3,), unit
    length, camera axes."""
    gen = np.random.default_rng(gen) if not isinstance(gen, np.random.Generator) else gen
    up = np.asarray(up_world, dtype=float)
    down = -(np.asarray(world_from_camera, dtype=float)[:3, :3].T @ (up / np.linalg.norm(up)))
    a = np.cross(down, [1.0, 0.0, 0.0] if abs(down[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(down, a)
    w = math.radians(sigma_deg) * (gen.normal() * a + gen.normal() * b)  # rotation vector
    return so3_exp(w) @ down


#: The detector model of the report's second noise setting (twice the default noise).
NOISY = dict(center_noise=0.08, axis_log_noise=0.12, angle_noise_rad=math.radians(8.0))


def reduce_indices(object_ids, n: int, rng: np.random.Generator) -> list[int] | None:
    """Indices of ``n`` of the frame's true detections (random subset), or None if fewer."""
    true = [i for i, o in enumerate(object_ids) if o is not None]
    if len(true) < n:
        return None
    return sorted(rng.choice(true, n, replace=False).tolist())


def reduce_frame(detections, object_ids, n: int, rng: np.random.Generator):
    """``n`` of the frame's true detections (random subset), or None if it has fewer."""
    keep = reduce_indices(object_ids, n, rng)
    return None if keep is None else [detections[i] for i in keep]
