"""Scan-to-scan ICP lidar odometry (seed 002, part 2): a 2D laser scan aligned to the
one before it, the wheel (or EKF) pose delta between them as the initial guess.

    src = voxel_downsample(scan_points(scan, mount), 0.02)      # base frame, metres
    dst = voxel_downsample(scan_points(previous, mount), 0.02)
    result = icp(src, dst, initial=(dx, dy, dtheta), method="point_to_line", normal_neighbors=12)
    result.pose        # (x, y, theta): the source's frame in the target's
    result.ok          # converged, enough inliers, and no direction left unconstrained

    odom = IcpOdometry(mount)
    odom.update(scan, wheel_delta)   # the pose so far; odom.fallbacks counts the misses

A pose ``(x, y, theta)`` maps a point ``p`` of the source's frame to ``R(theta) p + (x,
y)`` in the target's. Each iteration pairs every source point (moved by the current
pose) with its nearest target point (``scipy.spatial.cKDTree``), drops the pairs
farther apart than ``max_correspondence_distance`` and, optionally, the worst
``trim_fraction`` of the rest, then solves for the pose:

- ``point_to_point``: the closed-form least-squares rigid transform of the pairs
  (Arun, Huang and Blostein 1987, the SVD of the cross-covariance; Kabsch's
  reflection guard);
- ``point_to_line``: one Gauss-Newton step on the distances from the moved source
  points to the lines through their target points (the target's normals, from the
  principal axes of each target point's ``normal_neighbors`` nearest neighbours): the
  metric of Censi's PL-ICP, linearised in the pose.

It stops when the pose changes by less than ``tolerance`` (metres, and radians), or
comes back within it of the pose two iterations before while it moves by less than a
hundred times it (two sets of pairings, each giving the other's pose), or after
``max_iterations``. ``converged`` says it stopped on the tolerance with at least
``min_inliers`` pairs and ``min_inlier_fraction`` of the source's points paired.
``degenerate`` says the paired target normals leave a direction of translation
unconstrained (a corridor's walls: the smaller eigenvalue of the mean of ``n n^T`` under
``degenerate_ratio`` of the larger), whichever method ran: the pose along that direction
is then only the initial guess. Neither flag can see a wrong basin that fits as well as
the right one (a periodic or symmetric room): ``IcpOdometry`` also rejects a result
more than ``max_jump`` from its guess.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.spatial import cKDTree

from wcdrive.plant.lidar import LaserScan, LidarMount

Pose2D = tuple[float, float, float]
Method = Literal["point_to_point", "point_to_line"]


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def compose(a: Pose2D, b: Pose2D) -> Pose2D:
    """``a`` then ``b`` (``b`` given in ``a``'s frame): the pose ``a * b``."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], _wrap(a[2] + b[2]))


def relative(a: Pose2D, b: Pose2D) -> Pose2D:
    """The pose of ``b`` in ``a``'s frame: ``a^-1 * b``."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, _wrap(b[2] - a[2]))


def transform(points: np.ndarray, pose: Pose2D) -> np.ndarray:
    """``points`` (N, 2) moved by ``pose``: ``R(theta) p + (x, y)``."""
    return np.asarray(points, dtype=float) @ _rot(pose[2]).T + np.array(pose[:2])


def scan_points(scan: LaserScan, mount: LidarMount | None = None) -> np.ndarray:
    """The scan's returns as (N, 2) points, in beam order: beam ``i`` at
    ``angle_min + i * angle_increment`` in the laser frame (the driver's published
    angles), ranges outside ``[range_min, range_max]`` or not finite left out. With
    ``mount`` the points are in the chair's base frame: the laser frame's roll (pi for
    a head-down mount whose driver is not told) flips y, then the mount's yaw and
    offset."""
    ranges = np.asarray(scan.ranges, dtype=float)
    angles = scan.angle_min + np.arange(len(ranges)) * scan.angle_increment
    keep = np.isfinite(ranges) & (ranges >= scan.range_min) & (ranges <= scan.range_max)
    r, a = ranges[keep], angles[keep]
    points = np.column_stack((r * np.cos(a), r * np.sin(a)))
    if mount is None:
        return points
    if mount.tf_roll:
        points[:, 1] = -points[:, 1]
    return transform(points, (mount.x, mount.y, math.radians(mount.yaw_deg)))


def voxel_downsample(points: np.ndarray, size: float) -> np.ndarray:
    """The centroid of the points in each ``size`` square cell (cells in the order of
    their first point): even density, and the range noise averaged within a cell."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if size <= 0 or len(pts) == 0:
        return pts
    cells = np.floor(pts / size).astype(np.int64)
    _, first, inverse = np.unique(cells, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    sums = np.zeros((len(first), 2))
    np.add.at(sums, inverse, pts)
    counts = np.bincount(inverse, minlength=len(first)).astype(float)
    centroids = sums / counts[:, None]
    return centroids[np.argsort(first, kind="stable")]


def estimate_normals(points: np.ndarray, neighbors: int = 6, radius: float = 0.3,
                     tree: cKDTree | None = None) -> np.ndarray:
    """(N, 2) unit normals: each point's smallest principal axis of itself and its
    ``neighbors`` nearest points; 0 (no normal) where one of those is farther than
    ``radius`` (a lone or sparse point: a wall seen at a grazing angle) or there are
    too few points."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    k = min(neighbors + 1, len(pts))
    if k < 3:
        return np.zeros_like(pts)
    tree = tree if tree is not None else cKDTree(pts)
    dist, idx = tree.query(pts, k=k)
    local = pts[idx] - pts[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local)
    _, vectors = np.linalg.eigh(cov)          # ascending eigenvalues
    normals = np.asarray(vectors[:, :, 0])
    normals[dist[:, -1] > radius] = 0.0
    return normals


@dataclass(frozen=True)
class IcpResult:
    """One alignment: the source's pose in the target's frame, how it ended, and
    ``covariance`` (3x3 over x, y, theta): the residual variance times the inverse of
    the last step's Gauss-Newton information matrix (``inf`` where it is singular)."""

    pose: Pose2D
    iterations: int
    converged: bool
    rms: float
    inliers: int
    inlier_fraction: float
    degenerate: bool
    covariance: np.ndarray = field(repr=False)

    @property
    def ok(self) -> bool:
        """Converged and not degenerate: a pose to use."""
        return self.converged and not self.degenerate


def _kabsch(src: np.ndarray, dst: np.ndarray) -> Pose2D:
    """The rigid transform (no reflection) that moves ``src`` onto ``dst`` best in the
    least-squares sense."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    h = (src - mu_s).T @ (dst - mu_d)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, d]) @ u.T
    t = mu_d - r @ mu_s
    return float(t[0]), float(t[1]), math.atan2(r[1, 0], r[0, 0])


def icp(source: np.ndarray, target: np.ndarray, initial: Pose2D = (0.0, 0.0, 0.0),
        method: Method = "point_to_line", max_iterations: int = 50, tolerance: float = 1e-5,
        max_correspondence_distance: float = 0.5, trim_fraction: float = 0.0,
        normal_neighbors: int = 6, normal_radius: float = 0.3, min_inliers: int = 20,
        min_inlier_fraction: float = 0.6,
        degenerate_ratio: float = 0.02) -> IcpResult:
    """Aligns ``source`` (N, 2) to ``target`` (M, 2) from ``initial`` (module docstring):
    the pose of the source's frame in the target's. Deterministic."""
    if method not in ("point_to_point", "point_to_line"):
        raise ValueError(f"unknown ICP method {method!r}")
    src = np.asarray(source, dtype=float).reshape(-1, 2)
    dst = np.asarray(target, dtype=float).reshape(-1, 2)
    tree = cKDTree(dst)
    normals = estimate_normals(dst, normal_neighbors, normal_radius, tree)
    pose: Pose2D = (float(initial[0]), float(initial[1]), _wrap(float(initial[2])))
    settled = False
    before: Pose2D | None = None
    iterations = 0
    while iterations < max_iterations:
        iterations += 1
        si, ti, _ = _pairs(transform(src, pose), tree, max_correspondence_distance, trim_fraction)
        if method == "point_to_line":
            has = _has_normal(normals[ti])
            si, ti = si[has], ti[has]
        if len(si) < 3:
            break
        if method == "point_to_point":
            new = _kabsch(src[si], dst[ti])
        else:
            step = _line_step(src[si], dst[ti], normals[ti], pose)
            if step is None:
                break
            new = (pose[0] + step[0], pose[1] + step[1], _wrap(pose[2] + step[2]))
        change = _distance(new, pose)
        # a two-step cycle of pairings: back within the tolerance of the pose before
        cycle = before is not None and _distance(new, before) < tolerance and change < 100 * tolerance
        before, pose = pose, new
        if change < tolerance or cycle:
            settled = True
            break
    si, ti, dist = _pairs(transform(src, pose), tree, max_correspondence_distance, trim_fraction)
    if method == "point_to_line":
        has = _has_normal(normals[ti])
        si, ti, dist = si[has], ti[has], dist[has]
    inliers = len(si)
    fraction = inliers / len(src) if len(src) else 0.0
    if method == "point_to_point":
        residuals = dist
    else:
        residuals = np.einsum("ij,ij->i", transform(src[si], pose) - dst[ti], normals[ti])
    rms = float(np.sqrt(np.mean(residuals ** 2))) if inliers else math.inf
    degenerate = _degenerate(normals[ti], degenerate_ratio)
    covariance = _covariance(src[si], dst[ti], normals[ti], pose, method, residuals)
    converged = settled and inliers >= min_inliers and fraction >= min_inlier_fraction
    return IcpResult(pose, iterations, converged, rms, inliers, fraction, degenerate, covariance)


def _distance(a: Pose2D, b: Pose2D) -> float:
    """The larger of the position change (m) and the heading change (rad)."""
    return max(math.hypot(a[0] - b[0], a[1] - b[1]), abs(_wrap(a[2] - b[2])))


def _pairs(moved: np.ndarray, tree: cKDTree, max_distance: float, trim: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Source indices, target indices and distances of the kept nearest-neighbour pairs."""
    dist, ti = tree.query(moved, k=1, distance_upper_bound=max_distance)
    keep = np.flatnonzero(np.isfinite(dist) & (dist <= max_distance))
    if trim > 0 and len(keep):
        order = np.argsort(dist[keep], kind="stable")
        keep = np.sort(keep[order[: max(3, math.ceil(len(keep) * (1.0 - trim)))]])
    return keep, np.asarray(ti)[keep], dist[keep]


def _has_normal(normals: np.ndarray) -> np.ndarray:
    """Which of the normals are one (``estimate_normals`` gives 0 for none)."""
    return np.asarray(np.any(normals != 0.0, axis=1))


def _line_jacobian(src: np.ndarray, normals: np.ndarray, pose: Pose2D) -> np.ndarray:
    """d(n . (R p + t - q)) / d(x, y, theta) for each pair: (K, 3)."""
    rp = src @ _rot(pose[2]).T
    dtheta = normals[:, 0] * -rp[:, 1] + normals[:, 1] * rp[:, 0]
    return np.column_stack((normals[:, 0], normals[:, 1], dtheta))


def _line_step(src: np.ndarray, dst: np.ndarray, normals: np.ndarray, pose: Pose2D
               ) -> tuple[float, float, float] | None:
    """The Gauss-Newton step in (x, y, theta) on the point-to-line distances."""
    jac = _line_jacobian(src, normals, pose)
    res = np.einsum("ij,ij->i", transform(src, pose) - dst, normals)
    step, _, rank, _ = np.linalg.lstsq(jac, -res, rcond=None)
    if rank < 3:
        return None
    return float(step[0]), float(step[1]), float(step[2])


def _degenerate(normals: np.ndarray, ratio: float) -> bool:
    """Whether the normals leave a direction of translation unconstrained."""
    normals = normals[_has_normal(normals)]
    if len(normals) == 0:
        return True
    eig = np.linalg.eigvalsh(normals.T @ normals / len(normals))
    return bool(eig[0] < ratio * max(eig[1], 1e-300))


def _covariance(src: np.ndarray, dst: np.ndarray, normals: np.ndarray, pose: Pose2D, method: Method,
                residuals: np.ndarray) -> np.ndarray:
    """The residual variance times the inverse information matrix of the residuals'
    Jacobian in (x, y, theta)."""
    if method == "point_to_line":
        jac = _line_jacobian(src, normals, pose)
        scalars = len(residuals)
    else:
        rp = src @ _rot(pose[2]).T
        ones, zeros = np.ones(len(src)), np.zeros(len(src))
        jac = np.vstack((np.column_stack((ones, zeros, -rp[:, 1])), np.column_stack((zeros, ones, rp[:, 0]))))
        scalars = 2 * len(residuals)
    if scalars <= 3:
        return np.full((3, 3), math.inf)
    info = jac.T @ jac
    if np.linalg.matrix_rank(info) < 3:
        return np.full((3, 3), math.inf)
    sigma2 = float(np.sum(residuals ** 2)) / (scalars - 3)
    return np.asarray(sigma2 * np.linalg.inv(info))


class IcpOdometry:
    """Scan-to-scan lidar odometry: ``update(scan, guess)`` aligns each scan to the one
    before it from ``guess`` (the wheel or EKF pose delta since that scan, in its base
    frame) and moves the pose by the result; where the result is not ``ok`` or is more
    than ``max_jump`` (metres, radians) from the guess it moves by the guess instead
    and counts a fallback. Points are in the base frame (``mount``), voxel-downsampled
    to ``voxel`` metres; ``options`` go to ``icp`` (``normal_neighbors`` 12 unless
    given: 2 cm cells want more neighbours than 5 cm ones)."""

    def __init__(self, mount: LidarMount | None = None, start: Pose2D = (0.0, 0.0, 0.0),
                 voxel: float = 0.02, max_jump: tuple[float, float] = (0.3, math.radians(15.0)),
                 **options: object) -> None:
        self.mount = mount
        self.pose: Pose2D = start
        self.voxel = voxel
        self.max_jump = max_jump
        self.options: dict[str, object] = {"normal_neighbors": 12, **options}
        self.previous: np.ndarray | None = None
        self.last: IcpResult | None = None
        self.scans = 0
        self.fallbacks = 0

    def update(self, scan: LaserScan, guess: Pose2D = (0.0, 0.0, 0.0)) -> Pose2D:
        """Takes the next scan and the pose delta since the last; returns the pose."""
        points = voxel_downsample(scan_points(scan, self.mount), self.voxel)
        self.scans += 1
        if self.previous is None:
            self.previous = points
            return self.pose
        result = icp(points, self.previous, initial=guess, **self.options)  # type: ignore[arg-type]
        self.last = result
        jump = relative(guess, result.pose)
        near = math.hypot(jump[0], jump[1]) <= self.max_jump[0] and abs(jump[2]) <= self.max_jump[1]
        if result.ok and near:
            delta = result.pose
        else:
            delta = guess
            self.fallbacks += 1
        self.pose = compose(self.pose, delta)
        self.previous = points
        return self.pose
