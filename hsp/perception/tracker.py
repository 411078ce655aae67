"""Frame-to-frame 6D tracking of every object by point-to-plane ICP (Open3D).

For each object and frame: predict with damped constant velocity, crop the scene points
near the prediction (table removed, colour-gated by the object's palette), express them
in the predicted object frame and align them to the model's surface samples (exact
normals) with a Tukey-robust point-to-plane ICP, gates 15 mm then 6 mm. A point near
several objects goes to the one whose predicted surface is nearest. ICP is skipped when
the prediction already fits as well as the object's last solution (most objects, most
frames, are still), and its pose is kept only when it fits better than the prediction.
A multicoloured object without symmetry is checked for half turns its shape cannot tell
apart. Objects at rest are settled on their support and held while hidden
(:mod:`hsp.perception.rest`); when one comes to rest, its heading and position are taken
from the image edges of its creases (:mod:`hsp.perception.edges`), which depth hardly
fixes. A carried object is predicted where its grasp holds it (the running mean of its
pose in the end-effector's frame) and keeps the grasp's orientation while that explains the
frame as well as its own fit: what a frame leaves free, a round handle's roll, stays put.
Each pose is marked lost with too few supporting points and suspect with a fit looser
than the frame's depth noise there allows (σ = k·z², k measured below the table); and it
is ok only if the frame supports it (:mod:`hsp.perception.evidence`): enough of the
object's seen surface lies at its depth in its colours, not much less than usual
for that object, and, for an object the end-effector may carry, the depth image does not
see past it. A moving object the frame does not support is looked for again, with wider
ICP gates, from its grip if the end-effector carries it, from further along its way, from
where it was, and from the centre of its colours nearby; the best supported is kept. One
still not found is looked for further along its way in the next frames, and globally
after a few of them, like a lost one. A fast hand (5 cm between frames, three times the
first gate) is thus followed, and a pose left on another object's points is never ok.

The tracker is given its start poses; :mod:`hsp.perception.initialize` estimates them
from the first frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import open3d as o3d

from hsp.dataset.features import TrackStatus
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from hsp.geometry import compose, pose_from_matrix, pose_to_matrix, relative
from hsp.perception.edges import EdgeConfig, crease_edges, image_gradient, refine_on_edges
from hsp.perception.pointcloud import backproject, chromaticity, colour_match, palette_mask
from hsp.perception.evidence import Evidence, evidence, seen_through
from hsp.perception.rest import RestConfig, RestState
from hsp.sim.render import Mesh


@dataclass(frozen=True)
class TrackerConfig:
    stride: int = 2
    """Use every stride-th pixel row and column."""
    table_clearance_m: float = 0.003
    """Points lower than this above the table plane z = 0 are table ..."""
    table_sigmas: float = 3.0
    """... and, in the table's colours, lower than this many times the depth noise there
    (:func:`table_clearance`) ..."""
    table_colour_share: float = 0.02
    """... the colours of at least this share of the points measured below the table."""
    crop_margin_m: float = 0.03
    colour_tolerance: float = 0.06
    """Largest chromaticity distance from the object's palette."""
    gates_m: tuple[float, ...] = (0.015, 0.006)
    tukey_m: float = 0.01
    damping: float = 0.5
    """Fraction of the last frame's motion carried into the prediction."""
    min_points: int = 30
    """Fewest scene points that support a pose (else lost) ..."""
    min_seen: float = 0.5
    """... or this share of the points an object far away or small can show, if fewer
    (:func:`min_points`) ..."""
    min_points_floor: int = 10
    """... but never fewer than this."""
    suspect_rmse_m: float = 0.004
    """A fit is loose (suspect) if its inlier RMSE exceeds this ..."""
    suspect_sigmas: float = 1.5
    """... or this many times the frame's depth noise at the object (:func:`depth_noise`), if more:
    a canvas 1.2 m away fits its pose to 4 mm, its points' noise."""
    model_points: int = 1500
    redetect_after: int = 5
    """Frames an object stays lost before a global search; the next ones come after 2, 4, 8, …
    times as many (a nut under the socket is lost for seconds, and a search costs ~1 s)."""
    min_gain: float = 0.05
    """ICP's pose replaces the prediction only if it lowers the fit cost by this fraction:
    noise alone must not move an object along a direction its visible part leaves free."""
    max_points: int = 800
    """Scene points per object for ICP, evenly thinned beyond this."""
    skip_ratio: float = 1.1
    """ICP is skipped when the prediction's fit cost is within this factor of the cost at the
    object's last ICP solution (a still wheel, nuts at rest): the prediction is as good."""
    flip_margin: float = 0.15
    """Share of an object's points whose colour a half-turned pose must explain better to
    replace ICP's (see :func:`unflip`)."""
    edges: EdgeConfig = EdgeConfig()
    """Search of a resting object's heading and position on the image edges ..."""
    edges_again: EdgeConfig = EdgeConfig(max_turn_deg=4.0, turn_step_deg=1.0, shift_m=0.001, shift_step_m=0.001,
                                         fine_rounds=0)
    """... and when a settled one is looked for again (:class:`~hsp.perception.rest.RestConfig`'s
    ``edge_every``): near it only, 81 poses (not 3,000: 0.1–0.2 s a nut)."""
    rest: RestConfig = RestConfig()
    """When an object is at rest, and how it is held there."""
    edge_tolerance: float = 0.1
    """The edges' pose is kept only if it fits the depth points within this fraction of
    the fit cost where it started (a hand's edges next to a block must not pull it) ..."""
    edge_noise: float = 3.0
    """... or within this many times 6/N of it, if more: ICP's pose, fitted to N noisy points,
    lies below the truth's cost by about 6/N of it (six degrees of freedom fitted; a nut's
    44 points: 14 %, and 10° off was kept over the edges' 2°)."""
    max_seen_through: float = 0.15
    """A moving object whose camera-facing surface the depth image sees past on more than
    this share is not where its pose says: ICP slid it along itself (a brush dipped along
    its handle leaves half its old place filled). If the end-effector carries it, it is
    tried again from its grip; it is marked suspect if that does not fit either."""
    grip_frames: int = 30
    """A carried object's grip averages about this many frames (:func:`_grips`) ..."""
    grip_margin: float = 0.05
    """... and its orientation is the grip's (about the fit's centroid) while that explains
    the frame (evidence share) within this of the fit's: a round handle's roll, which a frame's
    correlated depth noise turns by 5–25°, stays where the grasp holds it."""
    carry_step_m: float = 0.003
    """An object that moves this far in a frame while keeping its pose relative to the
    end-effector (to a third of that) is carried by it, until it comes to rest."""
    min_explained: float = 0.5
    """A pose is ok only if at least this share of the object's surface samples that the
    frame sees supports it (at their depth, in their colour: :func:`~hsp.perception.evidence.explained`);
    ICP can fit a fast hand's few points, or a block's, from 10 cm away."""
    support_drop: float = 0.1
    """... and at most this much below the object's usual share (dark, small or two-coloured
    objects are explained less): a hand 1.5 cm off on the brush it holds is still half
    explained. The usual share rises at once to a frame's that is higher ..."""
    support_rate: float = 0.1
    """... and falls by this fraction of the difference to a frame's that is lower."""
    search_gates_m: tuple[float, ...] = (0.05, 0.015, 0.006)
    """ICP's gates when a moving object the frame does not explain is looked for again."""
    search_m: float = 0.1
    """How far beyond its prediction's reach such an object is looked for by its colours (m):
    a hand at 1.5 m/s between frames at 15 frames/s."""


def _face_cross(tri: np.ndarray) -> np.ndarray:
    """Edge cross product of each triangle ``(F, 3, 3)`` → ``(F, 3)``: twice the area along the normal."""
    return np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


def sample_surface(mesh: Mesh, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` points uniformly on the mesh surface, their face normals and face indices,
    ``(n, 3)``, ``(n, 3)``, ``(n,)`` (seeded, so that tracking is reproducible)."""
    v = mesh.vertices[mesh.triangles]  # (F, 3, 3)
    cross = _face_cross(v)
    area = np.linalg.norm(cross, axis=1)
    face = rng.choice(len(area), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    flip = r1 + r2 > 1
    r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
    a, b, c = v[face, 0], v[face, 1], v[face, 2]
    points = a + r1[:, None] * (b - a) + r2[:, None] * (c - a)
    return points, cross[face] / np.maximum(area[face], 1e-12)[:, None], face


def min_points(model: "SurfaceModel", distance: float, focal_px: float, cfg: TrackerConfig) -> int:
    """Fewest scene points that support ``model``'s pose at ``distance`` (m) from a camera of
    focal length ``focal_px``: ``cfg.min_points``, or ``cfg.min_seen`` of the points its mean
    silhouette covers at ``cfg.stride`` if fewer (a convex body's mean projected area is a
    quarter of its surface area, Cauchy), at least ``cfg.min_points_floor``. A nut 1.6 m
    away shows 25 points."""
    shown = model.area / 4 * (focal_px / (cfg.stride * max(distance, 1e-3))) ** 2
    return int(np.clip(cfg.min_seen * shown, cfg.min_points_floor, cfg.min_points))


class SurfaceModel:
    """Surface samples with normals and the colour palette of one object."""

    def __init__(self, mesh: Mesh, n_points: int, seed: int = 0, symmetry: str = "none") -> None:
        points, normals, face = sample_surface(mesh, n_points, np.random.default_rng(seed))
        self.sample_rgb = mesh.face_rgb[face]
        """Albedo (n_points, 3) at each surface sample."""
        self.surface, self.normals = points, normals
        """Surface samples and their normals ``(n_points, 3)`` in the object frame."""
        self.tree = cKDTree(points)
        self.cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        self.cloud.normals = o3d.utility.Vector3dVector(normals)
        self.radius = float(np.max(np.linalg.norm(mesh.vertices, axis=1)))
        self.palette = np.unique(np.round(mesh.face_rgb, 3), axis=0)
        """Albedo colours (K, 3) of the model's faces."""
        tri = mesh.vertices[mesh.triangles]
        self.face_centres = tri.mean(axis=1)
        self.face_area = 0.5 * np.linalg.norm(_face_cross(tri), axis=1)
        self.area = float(self.face_area.sum())
        self.face_rgb = mesh.face_rgb
        self.centroid = points.mean(axis=0)
        self.can_flip = symmetry == "none" and len(self.palette) > 1
        """Turned end for end, its shape could fit as well; only its colours tell."""
        self.creases = crease_edges(mesh)

    def colour_mask(self, rgb: np.ndarray, tol: float) -> np.ndarray:
        return palette_mask(rgb, self.palette, tol)


def _icp(model: SurfaceModel, points_obj: np.ndarray, cfg: TrackerConfig,
         camera_obj: np.ndarray | None = None, gates: tuple[float, ...] | None = None) -> tuple[np.ndarray, float, int]:
    """Correction ``T (4, 4)`` taking the points (in the predicted object frame) onto the
    model, the inlier RMSE and the inlier count at the last gate (``gates``, default
    ``cfg.gates_m``). With the camera position in the object frame, only model samples
    facing the camera are matched (back faces cannot have produced the points)."""
    target = model.cloud
    if camera_obj is not None:
        P, N = np.asarray(model.cloud.points), np.asarray(model.cloud.normals)
        facing = np.flatnonzero(np.sum(N * (camera_obj - P), axis=1) > 0)
        target = model.cloud.select_by_index(facing)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points_obj))
    T = np.eye(4)
    result = None
    for gate in gates or cfg.gates_m:  # the robust kernel no narrower than half the gate: a wide search must move
        est = o3d.pipelines.registration.TransformationEstimationPointToPlane(
            o3d.pipelines.registration.TukeyLoss(k=max(cfg.tukey_m, gate / 2)))
        result = o3d.pipelines.registration.registration_icp(
            src, target, gate, T, est, o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=20))
        T = result.transformation
    assert result is not None
    return T, float(result.inlier_rmse), int(len(result.correspondence_set))


def _fit(model: SurfaceModel, local: np.ndarray, cfg: TrackerConfig) -> tuple[float, int, float]:
    """Fit of points in the object frame to the model: mean truncated squared distance
    (m²), and the inlier count and RMSE within the last gate."""
    gate = cfg.gates_m[-1]
    d = model.tree.query(local, distance_upper_bound=gate)[0]
    inlier = d < gate
    rmse = float(np.sqrt(np.mean(d[inlier] ** 2))) if inlier.any() else np.inf
    return float(np.mean(np.minimum(d, gate) ** 2)), int(inlier.sum()), rmse


def _fit_cost(model: SurfaceModel, local: np.ndarray, cfg: TrackerConfig) -> float:
    """Mean truncated squared distance (m²) of points in the object frame to the model."""
    return _fit(model, local, cfg)[0]


def colour_agreement(model: SurfaceModel, local: np.ndarray, cols: np.ndarray, cfg: TrackerConfig) -> int:
    """Scene points (in the object frame) that lie on the model's surface, within the first
    tracking gate, where the model has their colour: a flipped brush puts its bristles where
    the handle is seen and scores low, though its shape fits as well."""
    d, j = model.tree.query(local, distance_upper_bound=cfg.gates_m[0])
    on = np.flatnonzero(np.isfinite(d))
    return int(np.count_nonzero(colour_match(cols[on], model.sample_rgb[j[on]], cfg.colour_tolerance)))


FLIPS = Rotation.from_rotvec(np.pi * np.eye(3)).as_matrix()
"""Half turns about the body x, y and z axes."""


def unflip(model: SurfaceModel, local: np.ndarray, cols: np.ndarray, cost: float, cfg: TrackerConfig) -> np.ndarray | None:
    """The half turn about the model's centroid, ``(4, 4)`` in the object frame, that
    explains the points' colours markedly better (``cfg.flip_margin`` of them) with a shape
    fit (``cost``: the points' :func:`_fit_cost` as they are) no worse; None when the pose is right."""
    c = model.centroid
    best, best_R = colour_agreement(model, local, cols, cfg) + cfg.flip_margin * len(local), None
    for R in FLIPS:
        turned = (local - c) @ R + c  # the points as the half-turned model sees them
        agree = colour_agreement(model, turned, cols, cfg)
        if agree > best and _fit_cost(model, turned, cfg) <= 1.5 * cost:
            best, best_R = agree, R
    if best_R is None:
        return None
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = best_R, c - best_R @ c
    return T


def settle_on_edges(model: SurfaceModel, pose: np.ndarray, points: np.ndarray, gradient: np.ndarray, period: float,
                    K: np.ndarray, T_world_cam: np.ndarray, cfg: TrackerConfig) -> tuple[np.ndarray, float] | None:
    """A resting object's ``pose (7,)`` turned and shifted onto the image edges of its creases
    (:func:`~hsp.perception.edges.refine_on_edges`) and the fit cost of its depth ``points
    (N, 3)`` there; None when they fit that pose worse than ``cfg.edge_tolerance`` and
    ``cfg.edge_noise`` allow."""
    edged = refine_on_edges(gradient, model.creases, pose, period, K, T_world_cam, cfg.edges)

    def cost(p: np.ndarray) -> float:
        return _fit_cost(model, (points - p[:3]) @ pose_to_matrix(p)[:3, :3], cfg)

    c = cost(edged)
    tolerance = max(cfg.edge_tolerance, cfg.edge_noise * 6 / max(len(points), 1))
    return (edged, c) if c <= (1 + tolerance) * cost(pose) else None


def _register(model: SurfaceModel, points: np.ndarray, cols: np.ndarray, pred: np.ndarray, fitted: float,
              cfg: TrackerConfig, gates: tuple[float, ...] | None = None) -> tuple[np.ndarray, float, int, float, bool]:
    """Pose of one object from the scene points it owns, starting at ``pred``: ICP unless
    the prediction fits as well as the last solution (cost ``fitted``), kept only if it fits
    better than the prediction; then the half-turn check. Returns the pose, the fit cost of
    the last ICP solution (``fitted`` when ICP was skipped), inliers, inlier RMSE and
    whether a half turn was undone."""
    pose = pred
    local = (points - pose[:3]) @ pose_to_matrix(pose)[:3, :3]
    cost, inliers, rmse = _fit(model, local, cfg)
    if cost > cfg.skip_ratio * fitted:  # else the prediction fits as well as the last solution
        corr, rmse, inliers = _icp(model, local, cfg, gates=gates)  # no culling here: it lost objects mid-turn
        moved = local @ corr[:3, :3].T + corr[:3, 3]
        cost_icp = _fit_cost(model, moved, cfg)
        if cost_icp < (1 - cfg.min_gain) * cost:
            pose = compose(pose, pose_from_matrix(np.linalg.inv(corr)))
            local, cost = moved, cost_icp
        # else no better than the prediction: a half-hidden canvas would slide along itself
        fitted = cost
    flip = unflip(model, local, cols, cost, cfg) if model.can_flip else None
    if flip is not None:
        pose = compose(pose, pose_from_matrix(flip))
    return pose, fitted, inliers, rmse, flip is not None


def turned_to(model: SurfaceModel, pose: np.ndarray, other: np.ndarray) -> np.ndarray:
    """``pose (7,)`` turned to ``other``'s orientation about the model's centroid: where a
    fit puts an object, as another estimate holds it."""
    c = pose_to_matrix(pose)[:3, :3] @ model.centroid + pose[:3]
    return np.concatenate([c - pose_to_matrix(other)[:3, :3] @ model.centroid, other[3:]])


def _grips(poses: np.ndarray, ok: np.ndarray, prev: np.ndarray, in_hand: np.ndarray, grip: np.ndarray,
           count: np.ndarray, cfg: TrackerConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the end-effector (object 0) carries, as grips (poses in its frame, ``(n, 7)``,
    NaN for none) updated with one frame's ``poses (n, 7)`` (``ok (n,)``; ``prev``: last
    frame's poses, ``in_hand``: last frame's poses in the end-effector's frame). An object
    that moved more than ``carry_step_m`` while its pose in the end-effector's frame changed
    by under a third of that moves with it: carried, until it comes to rest (the caller
    drops its grip). A grasp is rigid: the grip is the running mean of the frames' relative
    poses (``count (n,)``: how many, up to ``cfg.grip_frames``; then an exponential mean), so
    what one frame's fit leaves free (a round handle's roll) does not wander. A carried
    object's grip is kept while ICP slides it out of it. Returns grips, relative poses, counts."""
    rel = np.full_like(in_hand, np.nan)
    if ok[0]:
        rel[ok] = relative(poses[ok], np.repeat(poses[:1], int(ok.sum()), axis=0))
    rel[0] = np.nan
    step = np.linalg.norm(poses[:, :3] - prev[:, :3], axis=1)
    with np.errstate(invalid="ignore"):
        together = (step > cfg.carry_step_m) & (np.linalg.norm(rel[:, :3] - in_hand[:, :3], axis=1) < step / 3)
    grip, count = grip.copy(), np.where(np.isnan(grip[:, 0]), 0, count)
    count[together] = np.minimum(count[together] + 1, cfg.grip_frames)
    i = np.flatnonzero(together)
    if i.size:
        w = 1.0 / count[i]
        start = np.where(count[i, None] == 1, rel[i], grip[i])
        R0 = Rotation.from_quat(start[:, 3:])
        turn = (R0.inv() * Rotation.from_quat(rel[i, 3:])).as_rotvec()
        grip[i, :3] = start[:, :3] + w[:, None] * (rel[i, :3] - start[:, :3])
        grip[i, 3:] = (R0 * Rotation.from_rotvec(w[:, None] * turn)).as_quat()
    return grip, rel, count


def _owned(owner: np.ndarray, i: int, cfg: TrackerConfig) -> np.ndarray:
    """Indices of the scene points object ``i`` owns, thinned evenly to at most about
    ``cfg.max_points`` (a wheel's top: thousands)."""
    sel = np.flatnonzero(owner == i)
    return sel[:: -(-sel.size // cfg.max_points)] if sel.size > cfg.max_points else sel


def _seen_past(model: SurfaceModel, pose: np.ndarray, depth: np.ndarray, K: np.ndarray,
               T_world_cam: np.ndarray) -> float:
    """:func:`~hsp.perception.evidence.seen_through` of ``model`` at world ``pose (7,)``."""
    return seen_through(model.surface, model.normals, pose_to_matrix(pose), depth, K, T_world_cam)


def evidence_at(model: SurfaceModel, pose: np.ndarray, rgb: np.ndarray, depth: np.ndarray, K: np.ndarray,
                T_world_cam: np.ndarray, cfg: TrackerConfig) -> Evidence:
    """:func:`~hsp.perception.evidence.evidence` of ``model`` at world ``pose (7,)``."""
    return evidence(model.surface, model.normals, model.sample_rgb, pose_to_matrix(pose), rgb, depth, K, T_world_cam,
                    cfg.colour_tolerance)


def colour_centre(model: SurfaceModel, pts: np.ndarray, cols: np.ndarray, pose: np.ndarray, reach: float,
                  cfg: TrackerConfig) -> np.ndarray | None:
    """``pose (7,)`` moved so that the model's centroid lies on the centroid of the points
    ``(N, 3)`` of its colours within ``reach`` of it; None when there are too few."""
    near = np.flatnonzero(np.sum((pts - pose[:3]) ** 2, axis=1) < reach**2)
    near = near[model.colour_mask(cols[near], cfg.colour_tolerance)]
    if near.size < cfg.min_points:
        return None
    centroid = pose_to_matrix(pose)[:3, :3] @ model.centroid + pose[:3]
    return np.concatenate([pose[:3] + pts[near].mean(axis=0) - centroid, pose[3:]])


def _search(i: int, starts: list[np.ndarray], pred: np.ndarray, pts: np.ndarray, cols: np.ndarray,
            models: list[SurfaceModel], known: np.ndarray, support: Callable[[np.ndarray], float], floor: float,
            noise_m: float, cfg: TrackerConfig) -> tuple[np.ndarray, float, int, float] | None:
    """Object ``i`` registered again from each of ``starts`` (poses ``(7,)``; the others'
    predictions ``pred`` decide which points are its), ICP with ``cfg.search_gates_m``: the
    pose, fit cost, index and ``support`` of the start whose registration fits (status ok at
    depth noise ``noise_m``) and the frame supports best, if above ``floor``."""
    best = None
    reach = models[i].radius + cfg.crop_margin_m + max(np.linalg.norm(p[:3] - pred[i, :3]) for p in starts)
    near = np.flatnonzero(np.sum((pts - pred[i, :3]) ** 2, axis=1) < reach**2)  # the points any start can own
    pts, cols = pts[near], cols[near]
    for k, start in enumerate(starts):
        trial = pred.copy()
        trial[i] = start
        sel = _owned(assign_points(pts, cols, models, trial, cfg, known), i, cfg)
        if sel.size < cfg.min_points:
            continue
        pose, cost, inliers, rmse, _ = _register(models[i], pts[sel], cols[sel], start, 0.0, cfg, cfg.search_gates_m)
        if _status(inliers, rmse, noise_m, cfg) != TrackStatus.OK:
            continue
        share = support(pose)
        if share > floor:
            best, floor = (pose, cost, k, share), share
    return best


def _status(inliers: int, rmse: float, noise_m: float, cfg: TrackerConfig) -> TrackStatus:
    """Lost with too few supporting points, suspect with a fit looser than its points'
    depth noise ``noise_m`` (σ) allows, else ok."""
    if inliers < cfg.min_points:
        return TrackStatus.LOST
    return TrackStatus.SUSPECT if rmse > max(cfg.suspect_rmse_m, cfg.suspect_sigmas * noise_m) else TrackStatus.OK


def assign_points(pts: np.ndarray, cols: np.ndarray, models: list[SurfaceModel], pred: np.ndarray,
                  cfg: TrackerConfig, active: np.ndarray | None = None) -> np.ndarray:
    """Owner of each scene point ``(N,)``: the object whose predicted surface is nearest,
    among those whose crop and colour palette admit the point; −1 for none. Occluding and
    touching objects (a hand on a block, nuts on a wheel) thus never share points."""
    best = np.full(len(pts), np.inf)
    owner = np.full(len(pts), -1)
    radius = np.array([m.radius for m in models]) + cfg.crop_margin_m
    d2 = np.sum(pts**2, axis=1)[:, None] - 2 * pts @ pred[:, :3].T + np.sum(pred[:, :3] ** 2, axis=1)  # (N, n)
    for i, model in enumerate(models):
        if active is not None and not active[i]:
            continue
        cand = np.flatnonzero(d2[:, i] < radius[i] ** 2)
        cand = cand[model.colour_mask(cols[cand], cfg.colour_tolerance)]
        if cand.size > 2 * cfg.max_points:  # a wheel's top: ICP takes max_points of them anyway
            cand = cand[:: cand.size // (2 * cfg.max_points)]
        if cand.size == 0:
            continue
        local = (pts[cand] - pred[i, :3]) @ pose_to_matrix(pred[i])[:3, :3]
        d = model.tree.query(local, distance_upper_bound=cfg.crop_margin_m)[0]
        closer = d < best[cand]
        best[cand[closer]] = d[closer]
        owner[cand[closer]] = i
    return owner


def predict(prev: np.ndarray, dx: np.ndarray, drot: np.ndarray, alpha: float) -> np.ndarray:
    """Damped constant velocity: the centre moves on by α·Δx and the orientation turns by
    α of the last rotation (about the object's own centre), ``(n, 7)``."""
    q = (Rotation.from_rotvec(alpha * drot) * Rotation.from_quat(prev[:, 3:])).as_quat()
    return np.concatenate([prev[:, :3] + alpha * dx, q], axis=1)


Support = Callable[[int, np.ndarray], float]
"""``(object index, world pose (7,)) → share``: how far the frame supports the object there
(:func:`evidence_at`'s share)."""
Redetect = Callable[[np.ndarray, np.ndarray, list[int], Support], tuple[np.ndarray, np.ndarray]]
"""``(points, colours, object indices, support) → (poses (k, 7), found (k,))``: a global search
for lost objects among the scene points no tracked object claims."""


def depth_noise(heights: np.ndarray, depth: np.ndarray, rays_z: np.ndarray, min_points: int) -> float:
    """The frame's depth noise scale k (m⁻¹): a stereo camera's depth error σ grows with the
    squared depth z along the pixel's ray, σ = k·z², from the points measured below the table
    plane (table and noise alone; ``heights (N,)`` < 0), whose height error is σ·|``rays_z``|
    (the height change per metre of depth); a half normal's median is 0.674 σ. NaN with
    fewer than ``min_points`` such points."""
    below = heights < 0
    if np.count_nonzero(below) < min_points:
        return float("nan")
    return float(np.median(-heights[below] / np.maximum(depth[below] ** 2 * np.abs(rays_z[below]), 1e-9)) / 0.674)


def table_clearance(pts: np.ndarray, cols: np.ndarray, depth: np.ndarray, rays_z: np.ndarray, k: float,
                    cfg: TrackerConfig) -> np.ndarray:
    """Height above the table plane z = 0 below which each world point ``(N, 3)`` of colour
    ``cols (N, 3)`` is table ``(N,)``: ``cfg.table_clearance_m``; for a point in the table's
    colours, ``cfg.table_sigmas`` times the height noise of a table point there if more:
    k·depth²·|rays_z| (:func:`depth_noise`'s ``k``).

    The points measured below the plane are table and noise alone (nothing is there); they
    give the table's colours (chromaticity bins holding ``cfg.table_colour_share`` of them).
    From 1.8 m, a table seen from above is 1 cm thick, and a hand has its colour; a 12 mm
    canvas lying on it keeps its points."""
    out = np.full(len(pts), cfg.table_clearance_m)
    below = pts[:, 2] < 0
    if np.isnan(k):
        return out
    bins = np.floor(chromaticity(cols)[:, :2] / (cfg.colour_tolerance / 2)).astype(np.int64)
    key = bins[:, 0] * 1000 + bins[:, 1]
    seen, count = np.unique(key[below], return_counts=True)
    table_like = np.isin(key, seen[count >= cfg.table_colour_share * count.sum()])
    noise = k * depth[table_like] ** 2 * np.abs(rays_z[table_like])
    out[table_like] = np.maximum(out[table_like], cfg.table_sigmas * noise)
    return out


def scene_points(rgb: np.ndarray, depth: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray,
                 cfg: TrackerConfig) -> tuple[np.ndarray, np.ndarray, float]:
    """World points and colours of one frame, table removed (:func:`table_clearance`), and
    the frame's depth noise scale k (:func:`depth_noise`)."""
    pts, cols = backproject(depth, rgb, K, T_world_cam, cfg.stride)
    z_cam = (pts - T_world_cam[:3]) @ pose_to_matrix(T_world_cam)[:3, 2]  # depth along the optical axis
    rays_z = (pts[:, 2] - T_world_cam[2]) / np.maximum(z_cam, 1e-9)
    k = depth_noise(pts[:, 2], z_cam, rays_z, cfg.min_points)
    keep = pts[:, 2] > table_clearance(pts, cols, z_cam, rays_z, k, cfg)
    return pts[keep], cols[keep], k


class FrameTracker:
    """The frame-to-frame tracker as a stream: ``update(rgb, depth)`` takes one frame and
    returns the world poses ``(n, 7)`` and status ``(n,)`` of every object, from world poses
    ``start (n, 7)`` at the first frame (``found (n,)`` says which of them are real). A lost
    object is searched for locally, from its last good pose, in every frame; once lost for
    ``cfg.redetect_after`` frames it is also searched for globally with ``redetect``, then
    less and less often. A lost object's pose is its last good one (or prediction), marked
    LOST.

    With ``rest``, objects at rest are settled on their support (:mod:`hsp.perception.rest`),
    and one that is hidden behind another while at rest is held there, marked SUSPECT.
    :func:`track` runs it over a recording; closed-loop evaluation feeds it rendered frames."""

    def __init__(self, K: np.ndarray, T_world_cam: np.ndarray, models: list[SurfaceModel], start: np.ndarray,
                 cfg: TrackerConfig = TrackerConfig(), found: np.ndarray | None = None,
                 redetect: Redetect | None = None, rest: RestState | None = None) -> None:
        n = len(models)
        self.K, self.T_world_cam, self.models, self.cfg, self.redetect, self.rest = K, T_world_cam, models, cfg, redetect, rest
        self.prev = start.copy()
        self.known = np.ones(n, bool) if found is None else found.copy()
        self.lost_for = np.where(self.known, 0, 1)
        self.dx, self.drot = np.zeros((n, 3)), np.zeros((n, 3))
        self.fitted = np.zeros(n)  # fit cost at each object's last ICP solution
        self.grip = np.full((n, 7), np.nan)  # pose in the end-effector's frame of what it carries (NaN: nothing)
        self.grip_count = np.zeros(n, np.int64)  # frames each grip averages
        self.in_hand = np.full((n, 7), np.nan)  # every object's pose in the end-effector's frame, last frame
        self.support_ref = np.full(n, np.nan)  # each object's usual support (TrackerConfig.support_drop)
        self.t = 0
        if rest is not None:
            rest.start(start, self.known)

    def _support(self, i: int, pose: np.ndarray, rgb: np.ndarray, depth: np.ndarray, anchored: bool) -> float:
        """How far the frame supports object ``i`` at ``pose``: the explained share of its seen
        surface (:func:`evidence_at`); 0 for an object the end-effector may carry when the depth
        image sees past much of it (ICP slides a long round handle along itself)."""
        ev = evidence_at(self.models[i], pose, rgb, depth, self.K, self.T_world_cam, self.cfg)
        if i > 0 and not anchored and ev.seen_through > self.cfg.max_seen_through:
            return 0.0
        return ev.share

    def _look_again(self, i: int, pred: np.ndarray, carried: bool, pts: np.ndarray, cols: np.ndarray,
                    owner: np.ndarray, rgb: np.ndarray, depth: np.ndarray, share: float, noise_m: float,
                    cfg: TrackerConfig) -> tuple[np.ndarray, float, bool, float] | None:
        """Moving object ``i``, lost or not explained at its prediction (``share``), searched
        for (:func:`_search`) from its grip on the end-effector if it is ``carried`` (then that
        is its prediction ``pred[i]``), its last pose moved on by the whole of its last motion,
        its last pose, and its colours' centre near the prediction: pose, fit cost, whether it
        is a correction (the grip), not motion, and its support."""
        ahead = 1.0 + self.lost_for[i]  # frames since its last pose to move on from
        starts = [predict(self.prev[i:i + 1], ahead * self.dx[i:i + 1], ahead * self.drot[i:i + 1], 1.0)[0]]
        if self.dx[i].any() or self.drot[i].any():  # else that is the last pose already
            starts.append(self.prev[i])
        reach = self.models[i].radius + self.cfg.search_m * (1 + self.lost_for[i])  # further for each frame it was not found
        free = (owner < 0) | (owner == i)  # not another object's
        centre = colour_centre(self.models[i], pts[free], cols[free], pred[i], reach, cfg)
        if centre is not None:
            starts.append(centre)
        if carried:
            starts.insert(0, pred[i])
        found = _search(i, starts, pred, pts, cols, self.models, self.known,
                        lambda p: self._support(i, p, rgb, depth, False), share, noise_m, cfg)
        if found is None:
            return None
        pose, cost, start, share = found
        return pose, cost, carried and start == 0, share

    def update(self, rgb: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poses ``(n, 7)`` and status ``(n,)`` in the frame ``rgb (H, W, 3)``, ``depth (H, W)`` m."""
        n = len(self.models)
        pose_t = np.zeros((n, 7))
        status_t = np.full(n, TrackStatus.OK, np.int64)
        turned = np.zeros(n, bool)
        measured = np.zeros(n, bool)  # ICP saw it (not held unseen, not lost)
        doubtful = np.zeros(n, bool)  # moving, and not found where the frame supports it
        by_grip = np.zeros(n, bool)  # the grasp's pose kept over the frame's own (fit)
        fit = np.zeros((n, 7))
        pts, cols, k = scene_points(rgb, depth, self.K, self.T_world_cam, self.cfg)
        pred = predict(self.prev, self.dx, self.drot, self.cfg.damping)
        owner = assign_points(pts, cols, self.models, pred, self.cfg, self.known)
        distance = np.linalg.norm(pred[:, :3] - self.T_world_cam[:3], axis=1)
        noise = np.nan_to_num(k * ((pred[:, :3] - self.T_world_cam[:3]) @ pose_to_matrix(self.T_world_cam)[:3, 2]) ** 2)
        for i in np.flatnonzero(self.known):
            cfg = replace(self.cfg, min_points=min_points(self.models[i], distance[i], self.K[0, 0], self.cfg))
            sel = _owned(owner, i, cfg)
            anchored = self.rest is not None and self.rest.anchored[i]  # a resting object has its own checks
            carried = i > 0 and status_t[0] != TrackStatus.LOST and not np.isnan(self.grip[i, 0])
            if carried:
                pred[i] = compose(pose_t[0], self.grip[i])  # where the grasp holds it
            if sel.size >= cfg.min_points:
                measured[i] = True
                last = self.fitted[i] if anchored else 0.0  # only what rests may skip ICP: a turning wrench moves little
                pose, self.fitted[i], inliers, rmse, turned[i] = _register(self.models[i], pts[sel], cols[sel], pred[i],
                                                                           last, cfg)
                status_t[i] = _status(inliers, rmse, noise[i], cfg)
            else:
                pose, status_t[i] = pred[i], TrackStatus.LOST
            share = 0.0 if status_t[i] == TrackStatus.LOST else self._support(i, pose, rgb, depth, anchored)
            floor = float(np.fmax(self.cfg.min_explained, self.support_ref[i] - self.cfg.support_drop))
            if share < floor:
                found = None if anchored else self._look_again(i, pred, carried, pts, cols, owner, rgb, depth, share,
                                                               noise[i], cfg)
                if found is not None:
                    pose, self.fitted[i], turned[i], share = found
                    status_t[i], measured[i] = TrackStatus.OK, True
                doubtful[i] = share < self.cfg.min_explained and not anchored
                if share < floor and status_t[i] == TrackStatus.OK:
                    status_t[i] = TrackStatus.SUSPECT
                elif anchored and not measured[i] and _seen_past(
                        self.models[i], pred[i], depth, self.K, self.T_world_cam) <= self.rest.cfg.max_seen_through:
                    status_t[i] = TrackStatus.SUSPECT  # hidden where it rests: held there
            if measured[i]:  # raised at once by a better supported frame, lowered slowly by worse ones
                r = self.support_ref[i]
                self.support_ref[i] = np.fmax(share, r + self.cfg.support_rate * (share - r))
            if carried and status_t[i] == TrackStatus.OK:
                grasped = turned_to(self.models[i], pose, pred[i])
                if self._support(i, grasped, rgb, depth, False) >= share - self.cfg.grip_margin:
                    by_grip[i], fit[i] = True, pose
                    pose = grasped  # the grasp explains the frame as well: what one fit leaves free stays put
            pose_t[i] = pose
        pose_t[~self.known], status_t[~self.known] = self.prev[~self.known], TrackStatus.LOST
        if self.rest is not None:
            seen = measured & (status_t != TrackStatus.LOST)
            through = lambda i, p: _seen_past(self.models[i], p, depth, self.K, self.T_world_cam)  # noqa: E731
            pose_t = self.rest.apply(pose_t, seen, through)
            look = np.flatnonzero(self.rest.fresh & self.rest.anchored & seen & (np.asarray(self.rest.periods) > 0))  # a heading to find
            gradient = image_gradient(rgb) if look.size else None
            for i in look:
                cfg = replace(self.cfg, edges=self.cfg.edges_again) if self.rest.edged[i] else self.cfg
                edged = settle_on_edges(self.models[i], pose_t[i], pts[owner == i], gradient, self.rest.periods[i], self.K,
                                        self.T_world_cam, cfg)
                if edged is not None:
                    pose_t[i], self.fitted[i] = self.rest.settle(i, edged[0]), edged[1]  # the solution to keep
                self.rest.fresh[i] = False
        k = self.lost_for // self.cfg.redetect_after  # searches after 1, 2, 4, 8, … × redetect_after lost frames
        search = np.flatnonzero((self.lost_for % self.cfg.redetect_after == 0) & (k > 0) & ((k & (k - 1)) == 0))
        if self.redetect is not None and search.size:
            found_poses, ok = self.redetect(pts[owner < 0], cols[owner < 0], search.tolist(),
                                            lambda i, p: self._support(i, p, rgb, depth, False))
            for i, p in zip(search[ok], found_poses[ok]):
                pose_t[i], status_t[i], self.known[i], doubtful[i] = p, TrackStatus.SUSPECT, True, False
        good = (status_t != TrackStatus.LOST) & ~doubtful  # a pose to move on from
        fit = np.where(by_grip[:, None], fit, pose_t)  # the grip learns from the frame's own poses
        self.grip, self.in_hand, self.grip_count = _grips(fit, status_t == TrackStatus.OK, self.prev, self.in_hand,
                                                          self.grip, self.grip_count, self.cfg)
        if self.rest is not None:
            self.grip[self.rest.anchored] = np.nan  # put down
        if self.t > 0:
            gap = 1.0 + self.lost_for
            moved = good & (gap <= 3)  # a velocity over at most three frames
            self.dx[moved] = (pose_t[moved, :3] - self.prev[moved, :3]) / gap[moved, None]
            self.drot[moved] = (Rotation.from_quat(pose_t[moved, 3:]) * Rotation.from_quat(self.prev[moved, 3:]).inv()
                                ).as_rotvec() / gap[moved, None]
        stop = (status_t == TrackStatus.LOST) | turned  # a doubtful object is looked for further along its way
        self.dx[stop], self.drot[stop] = 0.0, 0.0  # a half turn is a correction, not motion
        self.prev[good] = pose_t[good]
        self.lost_for = np.where(good, 0, self.lost_for + 1)
        self.t += 1
        return pose_t, status_t


def follow(tracker: FrameTracker, rgb: np.ndarray, depth: np.ndarray,
           progress: Callable[[], None] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Poses ``(T, n, 7)`` and status ``(T, n)``: ``tracker`` updated with every frame of
    ``rgb (T, H, W, 3)``, ``depth (T, H, W)`` in turn."""
    n = len(tracker.models)
    poses, status = np.zeros((len(depth), n, 7)), np.zeros((len(depth), n), np.int64)
    for t in range(len(depth)):
        poses[t], status[t] = tracker.update(rgb[t], depth[t])
        if progress is not None:
            progress()
    return poses, status


def track(rgb: np.ndarray, depth: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, models: list[SurfaceModel],
          start: np.ndarray, cfg: TrackerConfig = TrackerConfig(), found: np.ndarray | None = None,
          redetect: Redetect | None = None, progress: Callable[[], None] | None = None,
          rest: RestState | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Poses ``(T, n, 7)`` and status ``(T, n)`` over frames ``rgb (T, H, W, 3)``,
    ``depth (T, H, W)``: a :class:`FrameTracker` from ``start`` :func:`follow`-ing them."""
    return follow(FrameTracker(K, T_world_cam, models, start, cfg, found, redetect, rest), rgb, depth, progress)
