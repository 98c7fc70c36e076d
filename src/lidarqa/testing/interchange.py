"""A synthetic road interchange with known truth, for the 3D road reconstruction.

Two roads cross on two levels: road A runs along x at ground level with a
slight grade; road B runs along y over a bridge deck `deck_height` metres up,
with smooth ramps down to ground level at both ends. Terrain lies about 1 m
below the roads. The laser points have noise `sigma_point` plus a laser block
offset (σ `sigma_block`) that varies smoothly over the scene: it is common to a
neighbourhood, as the error model assumes, and points `block_size` metres apart
still share 61 % of it; under the deck only a few points reach road A (the scan angle).
Cars (boxes 1.5 m high) stand on both roads. The map polygons are the true road
outlines moved by `map_shift`, split so that polygon ``A_mid`` is mostly covered
by the deck (most of its points are deck points) and ``B_deck`` lies over it.
Reference points lie on paint strips every 2 m with height noise `sigma_ref`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["InterchangeScene", "make_interchange"]


@dataclass(frozen=True, eq=False)
class InterchangeScene:
    """A synthetic interchange (see :func:`make_interchange`).

    Attributes
    ----------
    points : ndarray of shape (N, 3)
        Laser points (m).
    classification : ndarray of shape (N,) uint8
        2 ground/road, 17 bridge deck, 1 cars.
    polygons : list of shapely Polygon
        Map polygons in map coordinates (true outlines moved by `map_shift`).
    polygon_ids : ndarray of shape (P,) object
        ``A_west``, ``A_mid``, ``A_east``, ``B_south``, ``B_deck``, ``B_north``.
    polygon_road : ndarray of shape (P,) int64
        True road of each polygon: 0 = A (lower), 1 = B (upper).
    map_shift : ndarray of shape (2,)
        Map minus true position (m); the shift that moves the map onto the
        laser data is ``-map_shift``.
    reference_xyz : ndarray of shape (R, 3)
        Paint-strip reference points (true frame), heights with noise `sigma_ref`.
    reference_road : ndarray of shape (R,) int64
    params : dict
    """

    points: np.ndarray
    classification: np.ndarray
    polygons: list
    polygon_ids: np.ndarray
    polygon_road: np.ndarray
    map_shift: np.ndarray
    reference_xyz: np.ndarray
    reference_road: np.ndarray
    params: dict = field(default_factory=dict)

    def true_height(self, xy: Any, road: Any) -> np.ndarray:
        """True height (m) of road 0 (A) or 1 (B) at true-frame locations `xy`."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        road = np.broadcast_to(np.asarray(road), (len(xy),))
        p = self.params
        za = p["grade"] * xy[:, 0]
        zb = _deck_profile(xy[:, 1], p["deck_height"], p["deck_half"], p["ramp_length"])
        u = (xy[:, 0] + xy[:, 1]) / np.sqrt(2.0)
        zc = _deck_profile(u, p.get("third_height", 0.0), p["deck_half"], p["ramp_length"])
        return np.where(road == 0, za, np.where(road == 1, zb, zc))


def _deck_profile(y: np.ndarray, height: float, half: float, ramp: float) -> np.ndarray:
    t = np.clip((np.abs(y) - half) / ramp, 0.0, 1.0)
    return height * (1.0 + np.cos(np.pi * t)) / 2.0


def _block_field(xy: np.ndarray, sigma: float, length: float, seed: int) -> np.ndarray:
    """Smooth Gaussian random field with σ `sigma` and correlation exp(-d²/(2·length²)) at `xy`."""
    from scipy.ndimage import gaussian_filter, map_coordinates

    if len(xy) == 0 or sigma <= 0:
        return np.zeros(len(xy))
    cell = min(5.0, length / 4.0)
    pad = 4.0 * length
    lo = xy.min(axis=0) - pad
    shape = tuple(np.ceil((xy.max(axis=0) + pad - lo) / cell).astype(int) + 2)
    noise = np.random.default_rng(seed).normal(0.0, 1.0, shape)
    s = length / np.sqrt(2.0) / cell  # kernel σ (cells): correlation exp(-d²/(4 s²))
    field = gaussian_filter(noise, s, mode="constant", truncate=4.0)
    field *= sigma * np.sqrt(4.0 * np.pi) * s  # white noise through the kernel: var 1/(4π s²)
    ij = ((xy - lo) / cell).T
    return map_coordinates(field, ij, order=1, mode="nearest")


def make_interchange(
    *,
    seed: int = 0,
    density: float = 4.0,
    deck_height: float = 8.0,
    map_shift: tuple[float, float] = (0.6, -0.45),
    sigma_point: float = 0.08,
    sigma_block: float = 0.058,
    sigma_ref: float = 0.09,
    under_deck_density: float = 0.3,
    n_cars: int = 12,
    length: float = 150.0,
    block_size: float = 25.0,
    third_level: bool = False,
    third_height: float = 14.0,
) -> InterchangeScene:
    """Make a two- or three-level interchange with known heights, map shift and references.

    Parameters
    ----------
    seed : int
    density : float, default 4.0
        Laser points per m² on open surfaces.
    deck_height : float, default 8.0
        Height of road B's deck above road A (m); 6–14 m is typical.
    map_shift : (float, float), default (0.6, -0.45)
        Displacement of the map polygons from the true road outlines (m).
    sigma_point, sigma_block : float
        Laser point noise and the σ of the per-tile laser block offset (m).
    sigma_ref : float, default 0.09
        Height noise of the paint-strip reference points (m).
    under_deck_density : float, default 0.3
        Points per m² that reach road A under the deck.
    n_cars : int, default 12
    length : float, default 150.0
        Half length of road A (m); road B is 25 m longer on each side.
    block_size : float, default 25.0
        Correlation length L (m) of the laser block offset: offsets at points d
        metres apart correlate by exp(-d²/(2L²)) (0.92 at 10 m, 0.61 at 25 m).
        Tiles with independent offsets would put jumps inside plane fits and
        TIN triangles that the error model treats as one offset.
    third_level : bool, default False
        Add road C (truth road 2) on the diagonal x = y, 10 m wide, on a deck
        `third_height` m up over the crossing of A and B, with ramps down to
        ground level; A, B and terrain under it get few points.
    third_height : float, default 14.0
        Height of road C's deck (m).

    Examples
    --------
    >>> s = make_interchange(seed=1, density=1.0)
    >>> len(s.polygons), s.points.shape[1]
    (6, 3)
    """
    import shapely

    rng = np.random.default_rng(seed)
    grade, half_a, half_b = 0.003, 5.0, 6.0
    deck_half, ramp = 25.0, length
    ylen = deck_half + ramp
    xlen = length
    params = {
        "grade": grade,
        "deck_height": float(deck_height),
        "deck_half": deck_half,
        "ramp_length": ramp,
        "density": density,
        "sigma_point": sigma_point,
        "sigma_block": sigma_block,
        "sigma_ref": sigma_ref,
        "seed": seed,
        "third_level": bool(third_level),
        "third_height": float(third_height) if third_level else 0.0,
    }

    def uniform(x0, x1, y0, y1, dens):
        n = rng.poisson(max(dens, 0.0) * (x1 - x0) * (y1 - y0))
        return np.column_stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)])

    def zb(y):
        return _deck_profile(y, deck_height, deck_half, ramp)

    # road B (upper) everywhere on its footprint
    b = uniform(-half_b, half_b, -ylen, ylen, density)
    b_z = zb(b[:, 1])
    # road A: open parts full density, under the deck sparse
    a = uniform(-xlen, xlen, -half_a, half_a, density)
    a = a[np.abs(a[:, 0]) > half_b]
    a_under = uniform(-half_b, half_b, -half_a, half_a, under_deck_density)
    a = np.vstack([a, a_under])
    a_z = grade * a[:, 0]
    # terrain about 1 m below the roads, outside the road footprints (sparse under the deck)
    pad = 10.0
    t = uniform(-xlen - pad, xlen + pad, -ylen - pad, ylen + pad, density)
    on_a = (np.abs(t[:, 1]) <= half_a) & (np.abs(t[:, 0]) <= xlen)
    on_b = (np.abs(t[:, 0]) <= half_b) & (np.abs(t[:, 1]) <= ylen)
    t = t[~on_a & ~on_b]
    t_under = uniform(-half_b, half_b, -deck_half, deck_half, under_deck_density)
    t_under = t_under[np.abs(t_under[:, 1]) > half_a]
    t = np.vstack([t, t_under])
    t_z = -1.0 + 0.2 * np.sin(t[:, 0] / 37.0) * np.cos(t[:, 1] / 53.0) + grade * t[:, 0]
    # cars: 4.5 x 1.8 m roofs 1.5 m above the road
    cars, car_z = [], []
    for i in range(n_cars):
        on_b_road = i % 2 == 1
        if on_b_road:
            cx, cy = rng.uniform(-3.5, 3.5), rng.uniform(-ylen + 10, ylen - 10)
            c = uniform(cx - 0.9, cx + 0.9, cy - 2.25, cy + 2.25, density)
            z = zb(c[:, 1]) + 1.5
        else:
            cx = rng.choice([-1, 1]) * rng.uniform(15, xlen - 10)
            cy = rng.uniform(-3, 3)
            c = uniform(cx - 2.25, cx + 2.25, cy - 0.9, cy + 0.9, density)
            z = grade * c[:, 0] + 1.5
        cars.append(c)
        car_z.append(z)
    car_xy = np.vstack(cars) if cars else np.empty((0, 2))
    car_zz = np.concatenate(car_z) if car_z else np.empty(0)

    # cars hide the road under them
    def hidden(xy):
        keep = np.ones(len(xy), dtype=bool)
        for c in cars:
            if len(c):
                lo, hi = c.min(axis=0), c.max(axis=0)
                keep &= ~(
                    (xy[:, 0] >= lo[0])
                    & (xy[:, 0] <= hi[0])
                    & (xy[:, 1] >= lo[1])
                    & (xy[:, 1] <= hi[1])
                )
        return keep

    ka, kb = hidden(a), hidden(b)
    c_xy, c_z, c_cls = np.empty((0, 2)), np.empty(0), np.empty(0, dtype=np.uint8)
    if third_level:
        r2 = np.sqrt(2.0)
        uv = uniform(-ylen, ylen, -5.0, 5.0, density)
        c_xy = np.column_stack([(uv[:, 0] - uv[:, 1]) / r2, (uv[:, 0] + uv[:, 1]) / r2])
        c_z = _deck_profile(uv[:, 0], third_height, deck_half, ramp)
        c_cls = np.where(np.abs(uv[:, 0]) <= deck_half, 17, 2).astype(np.uint8)

        def under_c(xy_, z_):
            u_ = (xy_[:, 0] + xy_[:, 1]) / r2
            v_ = (xy_[:, 1] - xy_[:, 0]) / r2
            inside = (np.abs(v_) <= 5.0) & (np.abs(u_) <= ylen)
            gap = _deck_profile(u_, third_height, deck_half, ramp) - z_
            thin = rng.uniform(size=len(z_)) > under_deck_density / max(density, 1e-9)
            return ~(inside & ((gap < 3.0) | thin))  # buried under the embankment, or shadowed

        ka &= under_c(a, a_z)
        kb &= under_c(b, b_z)
        kt = under_c(t, t_z)
        t, t_z = t[kt], t_z[kt]
    xy = np.vstack([a[ka], b[kb], t, car_xy, c_xy])
    z = np.concatenate([a_z[ka], b_z[kb], t_z, car_zz, c_z])
    cls = np.concatenate(
        [
            np.full(ka.sum(), 2),
            np.where(np.abs(b[kb, 1]) <= deck_half, 17, 2),
            np.full(len(t), 2),
            np.full(len(car_xy), 1),
            c_cls,
        ]
    ).astype(np.uint8)
    # laser block offsets: a smooth random field (a laser block's offset is common to a
    # neighbourhood, as the error model assumes) with correlation exp(-d²/(2·block_size²)),
    # plus point noise
    z = (
        z
        + _block_field(xy, sigma_block, block_size, seed + 7919)
        + rng.normal(0.0, sigma_point, len(z))
    )
    pts = np.column_stack([xy, z])
    order = rng.permutation(len(pts))
    pts, cls = pts[order], cls[order]
    # map polygons, displaced by map_shift
    sx, sy = map_shift
    boxes: list[tuple[str, int, Any]] = [  # a None box: a polygon added below
        ("A_west", 0, (-xlen, -half_a, -10.0, half_a)),
        ("A_mid", 0, (-10.0, -half_a, 10.0, half_a)),
        ("A_east", 0, (10.0, -half_a, xlen, half_a)),
        ("B_south", 1, (-half_b, -ylen, half_b, -deck_half)),
        ("B_deck", 1, (-half_b, -deck_half, half_b, deck_half)),
        ("B_north", 1, (-half_b, deck_half, half_b, ylen)),
    ]
    polys = [shapely.box(x0 + sx, y0 + sy, x1 + sx, y1 + sy) for _, _, (x0, y0, x1, y1) in boxes]
    if third_level:
        r2 = np.sqrt(2.0)
        for name, (u0, u1) in (
            ("C_sw", (-ylen, -deck_half)),
            ("C_mid", (-deck_half, deck_half)),
            ("C_ne", (deck_half, ylen)),
        ):
            uv = np.array([(u0, -5.0), (u1, -5.0), (u1, 5.0), (u0, 5.0)])
            xy_c = np.column_stack([(uv[:, 0] - uv[:, 1]) / r2, (uv[:, 0] + uv[:, 1]) / r2])
            boxes.append((name, 2, None))
            polys.append(shapely.Polygon(xy_c + [sx, sy]))
    # paint strips every 2 m: centre line and lane lines, 1 m inside the ends
    ra_x = np.arange(-xlen + 1.0, xlen - 1.0 + 1e-9, 2.0)
    ra = np.column_stack([np.tile(ra_x, 3), np.repeat([-2.5, 0.0, 2.5], len(ra_x))])
    rb_y = np.arange(-ylen + 1.0, ylen - 1.0 + 1e-9, 2.0)
    rb = np.column_stack([np.repeat([-3.0, 0.0, 3.0], len(rb_y)), np.tile(rb_y, 3)])
    ref_xy = np.vstack([ra, rb])
    ref_road = np.concatenate([np.zeros(len(ra), np.int64), np.ones(len(rb), np.int64)])
    if third_level:
        rc_u = np.arange(-ylen + 1.0, ylen - 1.0 + 1e-9, 2.0)
        uv = np.column_stack([np.tile(rc_u, 3), np.repeat([-2.5, 0.0, 2.5], len(rc_u))])
        rc = np.column_stack(
            [(uv[:, 0] - uv[:, 1]) / np.sqrt(2.0), (uv[:, 0] + uv[:, 1]) / np.sqrt(2.0)]
        )
        ref_xy = np.vstack([ref_xy, rc])
        ref_road = np.concatenate([ref_road, np.full(len(rc), 2, dtype=np.int64)])
    scene_tmp = InterchangeScene(
        points=pts,
        classification=cls,
        polygons=polys,
        polygon_ids=np.array([b_[0] for b_ in boxes], dtype=object),
        polygon_road=np.array([b_[1] for b_ in boxes], dtype=np.int64),
        map_shift=np.array([sx, sy], dtype=np.float64),
        reference_xyz=np.empty((0, 3)),
        reference_road=ref_road,
        params=params,
    )
    ref_z = scene_tmp.true_height(ref_xy, ref_road)
    ref_z = ref_z + np.random.default_rng(seed + 104729).normal(0.0, sigma_ref, len(ref_z))
    return InterchangeScene(
        points=pts,
        classification=cls,
        polygons=polys,
        polygon_ids=scene_tmp.polygon_ids,
        polygon_road=scene_tmp.polygon_road,
        map_shift=scene_tmp.map_shift,
        reference_xyz=np.column_stack([ref_xy, ref_z]),
        reference_road=ref_road,
        params=params,
    )
