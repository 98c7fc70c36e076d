"""Surface-growing segmentation and plane segmentation (:ref:`alg-segmentation`).

:func:`surface_growing` labels points into smooth planar segments (seed surfaces
grown by proximity and distance to the segment plane). :func:`segment_planes`
adds a least-squares plane per segment and the segment adjacency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .._arrays import colmax, colmin
from .._gridkernels import sort_runs_lex
from .._progress import ProgressCallback, report, stage
from .._validate import as_points, check_choice, check_positive, check_range
from ..errors import OptionError
from . import _kernels as K

__all__ = ["surface_growing", "segment_planes", "PlaneSegmentation", "SEED_METHODS"]

SEED_METHODS = ("hough", "pca", "ransac")
_METHOD_CODE = {"pca": 0, "hough": 1, "ransac": 2}


def _check_int(value: Any, name: str, lo: int) -> int:
    try:
        v = int(value)
    except (TypeError, ValueError) as exc:
        raise OptionError(f"{name} must be an integer, got {value!r}") from exc
    if v != value or v < lo:
        raise OptionError(f"{name} must be an integer >= {lo}, got {value!r}")
    if v > 2**62:  # the numeric kernels take 64-bit integers
        raise OptionError(f"{name} {value!r} is too large")
    return v


def canonical_points(points: np.ndarray, cell: float | None = None, *, anchored: bool = False
                     ) -> tuple[np.ndarray, np.ndarray]:
    """An input-order-free, spatially coherent permutation and the centred sorted points.

    Points are sorted by a voxel key (for memory locality), then x, y, z; they are
    centred on the bounding-box middle, which, unlike the mean, does not depend on
    the summation order.

    The voxels are cells of the kNN grid from the points' own corner; with `anchored`,
    cells of a power-of-two side on a grid through the origin of the coordinates, so
    the relative order of two points is the same in any subset of a cloud that gets
    the same side: a chunk of a catalog and the whole area order (and tie-break) their
    common points alike. `cell` (m) then fixes the side (the next power of two at or
    above it; e.g. from the growing radius); default: from the density of `points`.
    """
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64), points.copy()
    lo = colmin(points)
    hi = colmax(points)
    if not anchored:
        cell = K.cell_size(hi - lo, len(points), 20)
        ijk = np.floor((points - lo) / cell).astype(np.int64)
    else:
        if cell is None or not np.isfinite(cell) or cell <= 0:
            cell = K.cell_size(hi - lo, len(points), 20)
        cell = max(float(cell), float(np.max(hi - lo)) / 1e5, 1e-9)
        cell = 2.0 ** math.ceil(math.log2(cell))
        ijk = np.floor(points / cell).astype(np.int64)
        ijk -= colmin(ijk)
    dims = colmax(ijk) + 1
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    perm = np.argsort(key, kind="stable")
    # within a cell: lexicographic x, y, z (exact duplicates keep their input order)
    perm = sort_runs_lex(perm, key[perm], points)
    pts = np.ascontiguousarray(points[perm] - (lo + hi) / 2.0)
    return perm, pts


def surface_growing(
    points: Any,
    *,
    k_seed: int = 20,
    seed_dist: float = 0.15,
    min_seed_points: int = 10,
    hough_angle_step: float = 3.0,
    grow_radius: float = 0.5,
    grow_dist: float = 0.2,
    refit_growth: float = 0.2,
    min_segment_size: int = 10,
    seed_method: str = "pca",
    seed: int = 0,
    refine_boundaries: bool = True,
    progress: ProgressCallback | None = None,
) -> np.ndarray:
    """Segment points into planar surfaces by seed detection and surface growing.

    Trial points are visited in ascending order of the planarity residual
    λ₃/(λ₁+λ₂+λ₃) of their `k_seed` nearest neighbours (ties: lexicographic
    x, y, z). Around the next unlabelled trial point, a seed plane is found from
    its unlabelled neighbours and accepted when at least `min_seed_points` lie
    within `seed_dist` of it. The segment then grows: unlabelled points within
    `grow_radius` of a segment point and within `grow_dist` of the segment plane
    join; the plane is refitted (total least squares) whenever the segment has
    grown by `refit_growth`. Segments smaller than `min_segment_size` are
    released (label -1).

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z in metres.
    k_seed : int, default 20
        Neighbourhood size (points, including the trial point) for planarity and
        seed detection; N is used when N < k_seed.
    seed_dist : float, default 0.15
        Distance (m) of seed points to the seed plane; also the Hough ρ bin width.
    min_seed_points : int, default 10
        Points needed within `seed_dist` of the seed plane to accept a seed.
    hough_angle_step : float, default 3.0
        Angular step (degrees) of the Hough normal directions (tilt and azimuth).
    grow_radius : float, default 0.5
        Neighbourhood radius (m, 3D) of growing. A radius taking in more than
        1000 points on average is refused (OptionError): growing is local.
    grow_dist : float, default 0.2
        Maximum distance (m) of a joining point to the segment plane.
    refit_growth : float, default 0.2
        Relative growth (fraction) after which the segment plane is refitted.
    min_segment_size : int, default 10
        Segments with fewer points are released (-1).
    seed_method : {"pca", "hough", "ransac"}, default "pca"
        How the seed plane is found in the neighbourhood: one total-least-squares
        fit plus one refit on its inliers ("pca", fastest), a 3D Hough transform
        over normal directions and ρ bins ("hough", :ref:`alg-segmentation`), or 200 three-point
        RANSAC hypotheses ("ransac", randomised by `seed` and the trial point).
    seed : int, default 0
        Random seed for ``seed_method="ransac"``.
    refine_boundaries : bool, default True
        After growing, move each point that lies farther from its own segment's
        plane than 2x that segment's RMS residual to a segment it touches (a point
        of it within `grow_radius`) whose plane is nearer (within `grow_dist`).
        Without this, the segment grown first keeps the points of its neighbour
        that lie within `grow_dist` of its plane along their intersection line.

    Returns
    -------
    ndarray of shape (N,), int64
        Segment label per point, -1 for unsegmented points. Labels are numbered
        0, 1, ... in the order the segments were found, which does not depend on
        the input order of the points.

    Raises
    ------
    InvalidPointsError
        If `points` is not a finite (N, 3) array.
    OptionError
        If an option is out of range.

    Notes
    -----
    Fewer than 3 distinct points give all -1. The kernel is a numba loop over a
    hashed voxel grid (cell = `grow_radius`), so memory stays O(N).

    Examples
    --------
    >>> g = np.stack(np.meshgrid(np.arange(10.), np.arange(10.)), -1).reshape(-1, 2)
    >>> pts = np.column_stack([g, np.zeros(100)])
    >>> np.unique(surface_growing(pts, grow_radius=1.5)).tolist()
    [0]
    """
    pts_in = as_points(points)
    (k_seed, seed_dist, min_seed_points, hough_angle_step, grow_radius, grow_dist, refit_growth,
     min_segment_size, seed_method, seed) = _check_growing_options(
        k_seed, seed_dist, min_seed_points, hough_angle_step, grow_radius, grow_dist, refit_growth,
        min_segment_size, seed_method, seed)
    n = len(pts_in)
    labels_out = np.full(n, -1, dtype=np.int64)
    if n < 3:
        return labels_out
    perm, pts = canonical_points(pts_in)
    _check_neighbourhood(pts, grow_radius, "grow_radius")
    labels_out[perm] = _grow_sorted(pts, k_seed, seed_dist, min_seed_points, hough_angle_step,
                                    grow_radius, grow_dist, refit_growth, min_segment_size,
                                    seed_method, seed, refine_boundaries, progress=progress)
    report(progress, 1.0)
    return labels_out


def _grow_sorted(pts: np.ndarray, k_seed: int, seed_dist: float, min_seed_points: int,
                 hough_angle_step: float, grow_radius: float, grow_dist: float,
                 refit_growth: float, min_segment_size: int, seed_method: str, seed: int,
                 refine_boundaries: bool, knn: np.ndarray | None = None,
                 progress: ProgressCallback | None = None,
                 offset: np.ndarray | None = None) -> np.ndarray:
    """Surface growing on canonically sorted, centred points (validated options).

    `progress` gets coarse stage fractions (the growing itself is one compiled call):
    neighbours 0-0.35, planarity 0.4, growing 0.9, boundary refinement 1. `offset` is
    what was subtracted from the points (their grids are then laid through the origin
    of the original coordinates, the same for a chunk and the whole area).
    """
    n = len(pts)
    if n < 3 or _fewer_than_3_distinct(pts):
        return np.full(n, -1, dtype=np.int64)
    k = min(k_seed, n)
    if knn is None or knn.shape[1] != k:
        knn = K.knn(pts, k)
    report(progress, 0.35)
    planarity = K.planarity_knn(pts, knn)
    report(progress, 0.4)
    trial_order = np.lexsort((np.arange(n), planarity)).astype(np.int64)

    grid = K.build_grid(pts, grow_radius, offset=offset)
    dirs = K.hough_directions(hough_angle_step) if seed_method == "hough" else np.zeros((1, 3))
    labels = K.surface_growing_kernel(
        pts, trial_order, knn, k, _METHOD_CODE[seed_method], seed_dist, min_seed_points, dirs,
        seed, grow_radius * grow_radius, grow_dist, refit_growth, min_segment_size, *grid)
    report(progress, 0.9)
    if refine_boundaries and labels.max() >= 1:
        labels = _refine_boundaries(pts, labels, grow_radius, grow_dist, grid)
    return labels


# A neighbourhood radius is local: past this mean number of neighbours per point the
# growing and contact searches become quadratic (minutes and gigabytes on a small tile).
MAX_MEAN_NEIGHBOURS = 1000


def _centre(points: np.ndarray) -> np.ndarray:
    """The offset :func:`canonical_points` subtracts (the bounding-box middle)."""
    return (colmin(points) + colmax(points)) / 2.0


def _canonical_cell(grow_radius: float | None) -> float | None:
    """Voxel side of the canonical order for a growing radius (m): two radii, for locality."""
    return None if grow_radius is None else 2.0 * float(grow_radius)


def _check_neighbourhood(pts: np.ndarray, radius: float, name: str) -> None:
    """Refuse a user-given radius that takes in more than MAX_MEAN_NEIGHBOURS points on average.

    Counted exactly on an evenly spread sample of at most 256 points.
    """
    n = len(pts)
    if n <= MAX_MEAN_NEIGHBOURS:
        return
    rows = np.linspace(0, n - 1, min(n, 256)).astype(np.int64)
    # counted on a grid of one radius (a cKDTree of every point cost more than the count)
    cx, cy, cz, nyz, nz, keys, starts, order, _ = K.build_grid(pts, radius)
    counts = K.grid_count(pts, rows, float(radius) ** 2, cx, cy, cz, nyz, nz, keys, starts, order)
    mean = float(counts.mean())
    if mean > MAX_MEAN_NEIGHBOURS:
        # the radius that takes in about the allowed number, for the message
        sample = pts[rows]
        dist, _ = cKDTree(pts).query(sample, k=MAX_MEAN_NEIGHBOURS)
        usable = float(np.median(dist[:, -1]))
        raise OptionError(
            f"{name} {radius:g} m takes in ~{mean:,.0f} neighbours per point "
            f"(at most {MAX_MEAN_NEIGHBOURS} allowed): it must be a local radius, "
            f"about {usable:.2g} m or less on this cloud"
        )


def _check_growing_options(
    k_seed, seed_dist, min_seed_points, hough_angle_step, grow_radius, grow_dist, refit_growth,
    min_segment_size, seed_method, seed,
) -> tuple[int, float, int, float, float, float, float, int, str, int]:
    return (_check_int(k_seed, "k_seed", 3),
            check_positive(seed_dist, "seed_dist"),
            _check_int(min_seed_points, "min_seed_points", 3),
            check_range(hough_angle_step, "hough_angle_step", 0.0, 90.0, lo_open=True),
            check_positive(grow_radius, "grow_radius"),
            check_positive(grow_dist, "grow_dist"),
            check_positive(refit_growth, "refit_growth", allow_zero=True),
            _check_int(min_segment_size, "min_segment_size", 1),
            check_choice(seed_method, SEED_METHODS, "seed_method"),
            _check_int(seed, "seed", 0))


def _fewer_than_3_distinct(sorted_pts: np.ndarray) -> bool:
    """True if an array sorted so that equal rows are adjacent has fewer than 3 distinct rows."""
    change = np.any(sorted_pts[1:] != sorted_pts[:-1], axis=1)
    return int(change.sum()) + 1 < 3


def _refine_boundaries(pts: np.ndarray, labels: np.ndarray, grow_radius: float, grow_dist: float,
                       grid: tuple, n_iter: int = 2) -> np.ndarray:
    """Order-free reassignment of boundary points to the nearest touching segment plane.

    A boundary point is one with a point of another segment within `grow_radius`
    (found by :func:`~lidarqa.geometry._kernels.contact_pairs`); it moves to that
    segment when that plane is nearer than its own and within `grow_dist`.
    All points move at once (Jacobi), then the planes are refitted; `n_iter` rounds.
    """
    cx, cy, cz, nyz, nz, cell_keys, cell_start, order, _ = grid
    labels = labels.copy()
    for _ in range(n_iter):
        n_labels = int(labels.max()) + 1
        _, mean, normal, _, _ = K.segment_planes_tls(pts, labels, n_labels)
        ci, cj = K.contact_pairs(pts, labels, grow_radius * grow_radius, cx, cy, cz, nyz, nz,
                                 cell_keys, cell_start, order)
        if len(ci) == 0:
            break
        pt = np.concatenate([ci, cj])
        cand = np.concatenate([labels[cj], labels[ci]])
        own = labels[pt]
        d_c = np.abs(np.einsum("ij,ij->i", pts[pt] - mean[cand], normal[cand]))
        d_o = np.abs(np.einsum("ij,ij->i", pts[pt] - mean[own], normal[own]))
        ok = (d_c < d_o) & (d_c <= grow_dist)
        if not ok.any():
            break
        pt, cand, d_c = pt[ok], cand[ok], d_c[ok]
        srt = np.lexsort((cand, d_c, pt))
        pt, cand = pt[srt], cand[srt]
        first = np.concatenate([[True], pt[1:] != pt[:-1]])
        labels[pt[first]] = cand[first]
    return labels


@dataclass(frozen=True, eq=False)
class PlaneSegmentation:
    """Planar segments of a point cloud with their planes and adjacency.

    Attributes
    ----------
    labels : ndarray of shape (N,), int64
        Segment of each input point, -1 if none. Segments are numbered
        0..n_segments-1 in an order that does not depend on the input order.
    inliers : ndarray of shape (N,), bool
        Points used for the final plane fit of their segment (labelled points
        within `trim` RMS of the first fit).
    normal : ndarray of shape (L, 3)
        Unit normals (n_z >= 0).
    rho : ndarray of shape (L,)
        Offsets (m): ``normal · p = rho``.
    centroid : ndarray of shape (L, 3)
        Centroids of the inliers (m).
    n_points : ndarray of shape (L,)
        Points per segment (all labelled points).
    n_inliers : ndarray of shape (L,)
        Inliers per segment.
    rmse : ndarray of shape (L,)
        RMS orthogonal residual of the inliers (m).
    covariance : ndarray of shape (L, 4, 4)
        Covariance of (n_x, n_y, n_z, rho at the centroid), as in
        :class:`~lidarqa.geometry.planes.PlaneFit`.
    adjacency : ndarray of shape (M, 2), int64
        Pairs (a, b), a < b, of segments with points within `adjacency_dist`.
    contacts : ndarray of shape (M,), int64
        Number of such point pairs per adjacent segment pair.
    contact_i, contact_j : ndarray of shape (K,), int64
        The point pairs themselves (input indices), grouped by adjacency pair:
        pair m owns ``contact_i[contact_ptr[m]:contact_ptr[m+1]]``.
    contact_ptr : ndarray of shape (M + 1,), int64
    parameters : dict
        The options used, and ``point_spacing``: the median distance (m) of a
        point to its 10th nearest neighbour (None for fewer than 11 points).
    """

    labels: np.ndarray = field(repr=False)
    inliers: np.ndarray = field(repr=False)
    normal: np.ndarray = field(repr=False)
    rho: np.ndarray = field(repr=False)
    centroid: np.ndarray = field(repr=False)
    n_points: np.ndarray = field(repr=False)
    n_inliers: np.ndarray = field(repr=False)
    rmse: np.ndarray = field(repr=False)
    covariance: np.ndarray = field(repr=False)
    adjacency: np.ndarray = field(repr=False)
    contacts: np.ndarray = field(repr=False)
    contact_i: np.ndarray = field(repr=False)
    contact_j: np.ndarray = field(repr=False)
    contact_ptr: np.ndarray = field(repr=False)
    parameters: dict = field(default_factory=dict)

    @property
    def n_segments(self) -> int:
        """Number of segments found."""
        return len(self.rho)

    @property
    def sigma_rho(self) -> np.ndarray:
        """Standard deviation (m) of each plane's position at its centroid."""
        return np.sqrt(np.maximum(self.covariance[:, 3, 3], 0.0))

    def members(self, segment: int, *, inliers_only: bool = True) -> np.ndarray:
        """Input indices of the points of `segment`."""
        m = self.labels == segment
        if inliers_only:
            m &= self.inliers
        return np.flatnonzero(m)

    def to_dict(self) -> dict:
        """Summary for JSON: counts and statistics (not the per-point labels)."""
        n = len(self.labels)
        out = {
            "n_points": n,
            "n_segments": self.n_segments,
            "n_segmented_points": int((self.labels >= 0).sum()),
            "segmented_fraction": float((self.labels >= 0).mean()) if n else 0.0,
            "n_adjacent_pairs": int(len(self.adjacency)),
            "parameters": dict(self.parameters),
        }
        if self.n_segments:
            out["rmse_median_m"] = float(np.median(self.rmse))
            out["points_per_segment_median"] = float(np.median(self.n_points))
        return out


def _plane_stats(pts: np.ndarray, labels: np.ndarray, n_labels: int):
    """Vectorised TLS of every segment: counts, centroid, normal, rmse, covariance (L,4,4)."""
    cnt, mean, normal, w, v = K.segment_planes_tls(pts, labels, n_labels)
    dof = np.maximum(cnt - 3.0, 1.0)
    s2 = np.maximum(w[:, 0], 0.0) * cnt / dof
    c4 = np.zeros((n_labels, 4, 4))
    for k in (1, 2):
        gap = np.maximum(cnt * (w[:, k] - w[:, 0]), 1e-300)
        vk = v[:, :, k]
        c4[:, :3, :3] += (s2 / gap)[:, None, None] * vk[:, :, None] * vk[:, None, :]
    c4[:, 3, 3] = s2 / np.maximum(cnt, 1.0)
    rmse = np.sqrt(np.maximum(w[:, 0], 0.0))
    return cnt, mean, normal, rmse, c4, w


def segment_planes(
    points: Any,
    *,
    k_seed: int = 20,
    seed_dist: float = 0.15,
    min_seed_points: int = 10,
    hough_angle_step: float = 3.0,
    grow_radius: float | None = None,
    grow_dist: float = 0.2,
    refit_growth: float = 0.2,
    min_segment_size: int = 30,
    seed_method: str = "pca",
    seed: int = 0,
    max_rmse: float | None = 0.15,
    trim: float = 3.0,
    adjacency_dist: float | None = None,
    min_contacts: int = 3,
    progress: ProgressCallback | None = None,
) -> PlaneSegmentation:
    """Segment a cloud into planes: surface growing, a plane per segment, adjacency.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        x, y, z in metres (e.g. the building points, class 6, of a tile).
    k_seed, seed_dist, min_seed_points, hough_angle_step, grow_dist, refit_growth, seed_method, seed
        Passed to :func:`surface_growing` (lengths in metres, angles in degrees).
    grow_radius : float or None, default None
        Growing radius (m). None adapts it to the sampling: twice the median
        distance of a point to its 10th nearest neighbour, clipped to [0.5, 3] m
        (about 0.8 m at 20 pts/m² on surfaces, 1 m for an IGN LiDAR HD strip).
        A given radius taking in more than 1000 points on average is refused.
    min_segment_size : int, default 30
        Smallest segment kept (points); smaller segments become -1.
    max_rmse : float or None, default 0.15
        Segments whose plane RMS residual (m) exceeds this are dropped (-1):
        they are not planar (vegetation, clutter). None keeps all.
    trim : float, default 3.0
        After a first TLS fit, points farther than `trim` times the segment RMS
        from its plane stay labelled but are not inliers; the plane is refitted
        on the inliers. 0 disables trimming.
    adjacency_dist : float or None, default None (= `grow_radius`)
        Two segments are adjacent if some of their points lie within this
        distance (m) of each other.
    min_contacts : int, default 3
        Point pairs needed to call two segments adjacent.
    progress : callable, optional
        Called with the estimated fraction of the work done (0..1).

    Returns
    -------
    PlaneSegmentation
        Labels, inlier mask, plane parameters and covariance per segment, adjacency.

    Raises
    ------
    InvalidPointsError, OptionError
        For bad points or options.
    """
    pts_in = as_points(points)
    if grow_radius is not None:
        grow_radius = check_positive(grow_radius, "grow_radius")
    if adjacency_dist is not None:
        adjacency_dist = check_positive(adjacency_dist, "adjacency_dist")
    trim = check_positive(trim, "trim", allow_zero=True)
    if max_rmse is not None:
        max_rmse = check_positive(max_rmse, "max_rmse")
    min_contacts = _check_int(min_contacts, "min_contacts", 1)
    min_segment_size = _check_int(min_segment_size, "min_segment_size", 3)
    params = dict(k_seed=k_seed, seed_dist=seed_dist, min_seed_points=min_seed_points,
                  hough_angle_step=hough_angle_step, grow_radius=grow_radius, grow_dist=grow_dist,
                  refit_growth=refit_growth, min_segment_size=min_segment_size,
                  seed_method=seed_method, seed=seed)
    _check_growing_options(k_seed, seed_dist, min_seed_points, hough_angle_step,
                           grow_radius or 1.0, grow_dist, refit_growth, min_segment_size,
                           seed_method, seed)
    n = len(pts_in)
    # frame-free: grids and order through the coordinates' origin, kNN ties by index, so a
    # chunk of a catalog segments its planes as one run over the whole area (issue #26)
    perm, pts = canonical_points(pts_in, _canonical_cell(grow_radius), anchored=True)
    knn = K.knn(pts, min(k_seed, n), by_index=True) if n >= 3 else None
    spacing = _spacing_from_knn(pts, knn) if knn is not None else float("nan")
    if grow_radius is None:
        grow_radius = float(np.clip(2.0 * spacing, 0.5, 3.0)) if np.isfinite(spacing) else 0.5
    else:
        _check_neighbourhood(pts, grow_radius, "grow_radius")
    if adjacency_dist is None:
        adjacency_dist = grow_radius
    elif adjacency_dist > grow_radius:
        _check_neighbourhood(pts, adjacency_dist, "adjacency_dist")
    params.update(grow_radius=grow_radius, max_rmse=max_rmse, trim=trim,
                  adjacency_dist=adjacency_dist, min_contacts=min_contacts,
                  point_spacing=spacing if np.isfinite(spacing) else None)
    if n < 3:
        return _empty_segmentation(n, params)
    opts = _check_growing_options(k_seed, seed_dist, min_seed_points, hough_angle_step,
                                  grow_radius, grow_dist, refit_growth, min_segment_size,
                                  seed_method, seed)
    report(progress, 0.3)
    offset = _centre(pts_in)
    labels = _grow_sorted(pts, *opts, True, knn, progress=stage(progress, 0.3, 0.9),
                          offset=offset)
    if labels.max(initial=-1) < 0:
        report(progress, 1.0)
        return _empty_segmentation(n, params)
    n_labels = int(labels.max()) + 1
    cnt, mean, normal, rmse, c4, w = _plane_stats(pts, labels, n_labels)
    inl = labels >= 0
    if trim > 0:
        lab0 = np.where(inl, labels, 0)
        d = np.abs(np.einsum("ij,ij->i", pts - mean[lab0], normal[lab0]))
        inl &= d <= trim * rmse[lab0] + 1e-9
        cnt_i, mean, normal, rmse, c4, w = _plane_stats(pts, np.where(inl, labels, -1), n_labels)
    else:
        cnt_i = cnt
    keep = (cnt_i >= 3) & (cnt >= min_segment_size)
    # a segment must be a plane, not a line: second eigenvalue well above the first
    keep &= w[:, 1] > 4.0 * w[:, 0] + 1e-12
    if max_rmse is not None:
        keep &= rmse <= max_rmse
    # renumber the kept segments 0..L-1, keeping the order in which they were found
    new_id = np.full(n_labels, -1, dtype=np.int64)
    new_id[keep] = np.arange(int(keep.sum()))
    labels = np.where(labels >= 0, new_id[np.maximum(labels, 0)], -1)
    inl &= labels >= 0
    cnt, cnt_i = cnt[keep], cnt_i[keep]
    mean, normal, rmse, c4 = mean[keep], normal[keep], rmse[keep], c4[keep]
    n_seg = int(keep.sum())

    # adjacency from point pairs within adjacency_dist (numba over a hashed grid)
    grid = K.build_grid(pts, adjacency_dist, offset=offset)
    cx, cy, cz, nyz, nz, cell_keys, cell_start, order, _ = grid
    ci, cj = K.contact_pairs(pts, labels, adjacency_dist**2, cx, cy, cz, nyz, nz, cell_keys,
                             cell_start, order)
    la, lb = labels[ci], labels[cj]
    swap = la > lb
    ci, cj = np.where(swap, cj, ci), np.where(swap, ci, cj)
    la, lb = np.minimum(la, lb), np.maximum(la, lb)
    key = la * max(n_seg, 1) + lb
    srt = np.lexsort((cj, ci, key))
    key, ci, cj = key[srt], ci[srt], cj[srt]
    uk, start, counts = np.unique(key, return_index=True, return_counts=True)
    good = counts >= min_contacts
    base = max(n_seg, 1)
    adjacency = np.column_stack([uk[good] // base, uk[good] % base]).astype(np.int64)
    sel = np.repeat(good, counts)
    ptr = np.concatenate([[0], np.cumsum(counts[good])]).astype(np.int64)

    labels_out = np.empty(n, dtype=np.int64)
    labels_out[perm] = labels
    inl_out = np.empty(n, dtype=bool)
    inl_out[perm] = inl
    centroid = mean + offset
    rho = np.einsum("ij,ij->i", normal, centroid)
    report(progress, 1.0)
    return PlaneSegmentation(
        labels=labels_out, inliers=inl_out, normal=normal, rho=rho, centroid=centroid,
        n_points=cnt.astype(np.int64), n_inliers=cnt_i.astype(np.int64), rmse=rmse, covariance=c4,
        adjacency=adjacency, contacts=counts[good].astype(np.int64),
        contact_i=perm[ci[sel]], contact_j=perm[cj[sel]], contact_ptr=ptr, parameters=params)


def point_spacing(points: np.ndarray, k: int = 10, max_sample: int = 20000) -> float:
    """Median distance (m) of a point to its `k`-th nearest neighbour (on a fixed sample).

    The sample is every ``ceil(N / max_sample)``-th point in the canonical
    (lexicographic) order, so the value does not depend on the input order.
    """
    n = len(points)
    if n <= k:
        return float("nan")
    step = max(1, -(-n // max_sample))
    order = np.lexsort((points[:, 2], points[:, 1], points[:, 0]))
    sample = points[order[::step]]
    d, _ = cKDTree(points).query(sample, k=k + 1)
    return float(np.median(d[:, k]))


def _spacing_from_knn(pts: np.ndarray, knn: np.ndarray, k: int = 10,
                      max_sample: int = 20000) -> float:
    """Median distance (m) to the k-th neighbour from precomputed neighbour lists (a sample)."""
    n, kk = knn.shape
    if kk <= k:
        return point_spacing(pts, k=k)
    step = max(1, -(-n // max_sample))
    idx = np.arange(0, n, step)
    d = np.linalg.norm(pts[knn[idx]] - pts[idx, None, :], axis=2)
    d.sort(axis=1)
    return float(np.median(d[:, k]))


def _empty_segmentation(n: int, params: dict) -> PlaneSegmentation:
    z = np.zeros(0)
    zi = np.zeros(0, dtype=np.int64)
    return PlaneSegmentation(
        labels=np.full(n, -1, dtype=np.int64), inliers=np.zeros(n, dtype=bool),
        normal=np.zeros((0, 3)), rho=z, centroid=np.zeros((0, 3)), n_points=zi, n_inliers=zi,
        rmse=z, covariance=np.zeros((0, 4, 4)), adjacency=np.zeros((0, 2), dtype=np.int64),
        contacts=zi, contact_i=zi, contact_j=zi, contact_ptr=np.zeros(1, dtype=np.int64),
        parameters=params)
