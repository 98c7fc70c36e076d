"""Private geometry of the synthetic scenes: terrain model, planar faces, sampling.

Everything here works in the scene's *local* frame (origin at the lower-left
corner of the extent, z = 0 at the terrain reference); :mod:`.scenes` moves the
result to the requested origin at the very end.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__: list[str] = []

# ASPRS classification codes used by the scenes.
CLASS_OTHER = 1
CLASS_GROUND = 2
CLASS_LOW_VEG = 3
CLASS_MEDIUM_VEG = 4
CLASS_HIGH_VEG = 5
CLASS_BUILDING = 6
CLASS_NOISE = 7


def canonical_plane(normal: np.ndarray, rho: float) -> tuple[np.ndarray, float]:
    """Unit normal with n_z >= 0 (for vertical planes n_y >= 0, then n_x >= 0) and matching rho."""
    n = np.asarray(normal, dtype=np.float64)
    norm = float(np.linalg.norm(n))
    n = n / norm
    rho = float(rho) / norm
    flip = n[2] < 0 or (n[2] == 0 and (n[1] < 0 or (n[1] == 0 and n[0] < 0)))
    if flip:
        n = -n
        rho = -rho
    return n + 0.0, rho + 0.0  # no negative zeros


# --------------------------------------------------------------------- terrain


@dataclass(frozen=True, eq=False)
class TerrainModel:
    """Height of the synthetic terrain (bare earth) at any xy.

    ``z = z0 + gx*u + gy*v + sum(a * sin(kx*u + ky*v + phase)) + steps`` in the
    local frame ``(u, v) = R^T (xy - offset_xy)``, plus ``offset_z``. Curbs
    raise everything outside a road band by a step; embankments are linear
    ramps between two parallel break lines.

    Attributes
    ----------
    z0, gx, gy : float
        Reference height (m) and planar gradient (m/m).
    waves : ndarray of shape (k, 4)
        Undulation terms ``(amplitude m, kx rad/m, ky rad/m, phase rad)``.
    roads : ndarray of shape (m, 6)
        ``(px, py, ux, uy, half_width m, curb_height m)``: a road along the line
        through p with unit direction u; ground farther than `half_width` from
        the line is raised by `curb_height` (two curbs per road).
    embankments : ndarray of shape (m, 7)
        ``(px, py, ux, uy, start m, width m, height m)``: ground rises linearly
        by `height` over signed distances ``start .. start + width`` from the line.
    rotation : ndarray of shape (2, 2)
        Rotation of the local frame into world xy.
    offset : ndarray of shape (3,)
        Translation of the local frame into world coordinates (m).
    """

    z0: float = 0.0
    gx: float = 0.0
    gy: float = 0.0
    waves: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    roads: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    embankments: np.ndarray = field(default_factory=lambda: np.zeros((0, 7)))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(2))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def is_planar(self) -> bool:
        """True when the terrain is a single plane (no undulation, curbs or embankments)."""
        return len(self.waves) == 0 and len(self.roads) == 0 and len(self.embankments) == 0

    def plane(self) -> tuple[np.ndarray, float]:
        """World (normal, rho) of the terrain plane; only meaningful when :attr:`is_planar`."""
        n_local = np.array([-self.gx, -self.gy, 1.0])
        n_local /= np.linalg.norm(n_local)
        n = np.array([*(self.rotation @ n_local[:2]), n_local[2]])
        p0 = np.array([self.offset[0], self.offset[1], self.z0 + self.offset[2]])
        return canonical_plane(n, float(n @ p0))

    def height(self, xy: np.ndarray) -> np.ndarray:
        """Terrain height (m) at world positions `xy` of shape (N, 2)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        local = (xy - self.offset[:2]) @ self.rotation  # R^T applied to rows
        return self.local_height(local) + self.offset[2]

    def local_height(self, uv: np.ndarray, *, skip_road: int = -1) -> np.ndarray:
        """Height in the local frame (no offset); `skip_road` leaves one road's step out."""
        u = uv[:, 0]
        v = uv[:, 1]
        z = self.z0 + self.gx * u + self.gy * v
        for a, kx, ky, ph in self.waves:
            z = z + a * np.sin(kx * u + ky * v + ph)
        for i, (px, py, ux, uy, half, h) in enumerate(self.roads):
            if i == skip_road:
                continue
            d = (u - px) * (-uy) + (v - py) * ux
            z = z + h * (np.abs(d) >= half)
        for px, py, ux, uy, start, width, h in self.embankments:
            d = (u - px) * (-uy) + (v - py) * ux
            z = z + h * np.clip((d - start) / width, 0.0, 1.0)
        return z

    def moved(self, rotation2: np.ndarray, translation: np.ndarray) -> TerrainModel:
        """The same terrain after a rotation about z (2x2) and a translation."""
        t = np.asarray(translation, dtype=np.float64)
        new_rot = rotation2 @ self.rotation
        new_off = np.array([*(rotation2 @ self.offset[:2] + t[:2]), self.offset[2] + t[2]])
        return TerrainModel(self.z0, self.gx, self.gy, self.waves, self.roads, self.embankments,
                            new_rot, new_off)

    def breaklines(self, extent: tuple[float, float]) -> list[tuple[np.ndarray, np.ndarray, str]]:
        """Break lines clipped to the local extent, as (start_uv, end_uv, kind)."""
        out = []
        for px, py, ux, uy, half, _h in self.roads:
            for s in (-half, half):
                seg = _clip_line(np.array([px, py]), np.array([ux, uy]), s, extent)
                if seg is not None:
                    out.append((*seg, "curb"))
        for px, py, ux, uy, start, width, _h in self.embankments:
            for s, kind in ((start, "embankment_foot"), (start + width, "embankment_top")):
                seg = _clip_line(np.array([px, py]), np.array([ux, uy]), s, extent)
                if seg is not None:
                    out.append((*seg, kind))
        return out


def _clip_line(p: np.ndarray, u: np.ndarray, shift: float,
               extent: tuple[float, float]) -> tuple[np.ndarray, np.ndarray] | None:
    """Clip the line p + shift*n + t*u (n = u rotated +90 deg) to [0, W] x [0, H]."""
    n = np.array([-u[1], u[0]])
    q = p + shift * n
    lo, hi = -np.inf, np.inf
    for k, size in enumerate(extent):
        if abs(u[k]) < 1e-15:
            if q[k] < 0 or q[k] > size:
                return None
            continue
        t1 = (0 - q[k]) / u[k]
        t2 = (size - q[k]) / u[k]
        lo = max(lo, min(t1, t2))
        hi = min(hi, max(t1, t2))
    if hi <= lo:
        return None
    return q + lo * u, q + hi * u


# --------------------------------------------------------------------- faces


@dataclass
class Face:
    """A convex planar polygon to sample, with its plane and labels."""

    vertices: np.ndarray  # (k, 3), local frame, convex, in order
    plane: int  # index into the scene's plane list
    classification: int
    object_id: int
    density: float  # points per m^2 of *surface*
    clip_below_terrain: bool = False
    airborne: bool = False  # seen from above: a jittered grid is laid out in xy


def polygon_area(vertices: np.ndarray) -> float:
    """Area (m^2) of a planar convex polygon in 3D."""
    v0 = vertices[0]
    cross = np.cross(vertices[1:-1] - v0, vertices[2:] - v0)
    return 0.5 * float(np.linalg.norm(cross, axis=1).sum())


def sample_polygon(rng: np.random.Generator, vertices: np.ndarray, density: float) -> np.ndarray:
    """Uniform random points on a convex planar polygon, Poisson count density*area."""
    v0 = vertices[0]
    e1 = vertices[1:-1] - v0
    e2 = vertices[2:] - v0
    areas = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    total = float(areas.sum())
    n = int(rng.poisson(density * total)) if total > 0 and density > 0 else 0
    if n == 0:
        return np.zeros((0, 3))
    tri = rng.choice(len(areas), size=n, p=areas / total) if len(areas) > 1 else np.zeros(n, int)
    r = rng.random((n, 2))
    flip = r.sum(axis=1) > 1.0
    r[flip] = 1.0 - r[flip]
    return v0 + r[:, :1] * e1[tri] + r[:, 1:] * e2[tri]


def _jittered_grid(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray,
                   spacing: float) -> np.ndarray:
    """One uniform point per `spacing` cell of a randomly shifted grid covering [lo, hi]."""
    shift = rng.random(2) * spacing
    start = lo - shift
    n = np.maximum(np.ceil((hi - start) / spacing).astype(int), 1)
    i, j = np.meshgrid(np.arange(n[0]), np.arange(n[1]), indexing="ij")
    cells = np.column_stack([i.ravel(), j.ravel()]).astype(np.float64)
    p = start + (cells + rng.random(cells.shape)) * spacing
    return p[np.all((p >= lo) & (p <= hi), axis=1)]


def _inside_convex(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Mask of 2D points inside a convex polygon (either orientation)."""
    q = np.roll(poly, -1, axis=0)
    cross = ((q[:, 0] - poly[:, 0])[None] * (p[:, 1:2] - poly[:, 1][None])
             - (q[:, 1] - poly[:, 1])[None] * (p[:, 0:1] - poly[:, 0][None]))
    area2 = np.sum(poly[:, 0] * q[:, 1] - q[:, 0] * poly[:, 1])
    return np.all(cross * np.sign(area2) >= 0, axis=1)


def sample_polygon_jittered(rng: np.random.Generator, vertices: np.ndarray, density: float,
                            normal: np.ndarray, airborne: bool) -> np.ndarray:
    """Points of a jittered grid (one per cell of area 1/density) on a convex planar polygon.

    Airborne faces get the grid in horizontal xy at the horizontal density
    ``density / |n_z|`` (so ``density`` stays per m^2 of surface); other faces
    get it in the face's own (horizontal, up-slope) frame.
    """
    if density <= 0:
        return np.zeros((0, 3))
    v0 = vertices[0]
    if airborne and abs(normal[2]) > 1e-6:
        spacing = 1.0 / np.sqrt(density / abs(normal[2]))
        poly = vertices[:, :2]
        xy = _jittered_grid(rng, poly.min(axis=0), poly.max(axis=0), spacing)
        xy = xy[_inside_convex(xy, poly)]
        z = (normal @ v0 - xy @ normal[:2]) / normal[2]
        return np.column_stack([xy, z])
    u = np.cross([0.0, 0.0, 1.0], normal)
    if np.linalg.norm(u) < 1e-9:
        u = np.array([1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(normal, u)
    poly = np.column_stack([(vertices - v0) @ u, (vertices - v0) @ w])
    ab = _jittered_grid(rng, poly.min(axis=0), poly.max(axis=0), 1.0 / np.sqrt(density))
    ab = ab[_inside_convex(ab, poly)]
    return v0 + ab[:, :1] * u + ab[:, 1:] * w


# --------------------------------------------------------------------- placement


def rect_corners(center: np.ndarray, length: float, width: float, azimuth_deg: float) -> np.ndarray:
    """(4, 2) corners, counter-clockwise, of a rectangle; `length` runs along the azimuth.

    The azimuth is the direction of the long (local x) axis, counter-clockwise
    from +x, in degrees.
    """
    a = np.deg2rad(azimuth_deg)
    ex = np.array([np.cos(a), np.sin(a)])
    ey = np.array([-np.sin(a), np.cos(a)])
    hl, hw = 0.5 * length, 0.5 * width
    local = np.array([[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw]])
    return center + local[:, :1] * ex + local[:, 1:] * ey


def in_rectangle(xy: np.ndarray, center: np.ndarray, length: float, width: float,
                 azimuth_deg: float, margin: float = 0.0) -> np.ndarray:
    """Mask of `xy` inside the (optionally enlarged) rectangle."""
    a = np.deg2rad(azimuth_deg)
    d = xy - center
    lx = d[:, 0] * np.cos(a) + d[:, 1] * np.sin(a)
    ly = -d[:, 0] * np.sin(a) + d[:, 1] * np.cos(a)
    return (np.abs(lx) <= 0.5 * length + margin) & (np.abs(ly) <= 0.5 * width + margin)


class ColumnSampler:
    """Uniform random xy in [0, W] x [0, H], generated column by column (1 m wide).

    Points come out grouped by x column, so the points near an object are a
    contiguous slice (a view) without sorting millions of points.
    """

    def __init__(self, rng: np.random.Generator, n: int, size: tuple[float, float],
                 column: float = 1.0, *, jittered: bool = False) -> None:
        w, h = size
        if jittered:  # one point per cell of area w * h / n, grid columns of width `column`
            spacing = float(np.sqrt(w * h / max(n, 1)))
            xy = _jittered_grid(rng, np.zeros(2), np.array([w, h]), spacing)
            col = np.minimum((xy[:, 0] // spacing).astype(np.int64), int(np.ceil(w / spacing)) - 1)
            order = np.argsort(col, kind="stable")
            self.xy = np.take(xy, order, axis=0)
            self.ncol = int(np.ceil(w / spacing))
            counts = np.bincount(col, minlength=self.ncol)
            self.offsets = np.concatenate([[0], np.cumsum(counts)])
            self.column = spacing
            return
        ncol = max(1, int(np.ceil(w / column)))
        edges = np.minimum(np.arange(ncol + 1) * column, w)
        widths = np.diff(edges)
        counts = rng.multinomial(n, widths / widths.sum())
        self.offsets = np.concatenate([[0], np.cumsum(counts)])
        col = np.repeat(np.arange(ncol), counts)
        x = edges[col] + rng.random(n) * widths[col]
        y = rng.random(n) * h
        self.xy = np.column_stack([x, y])
        self.column = column
        self.ncol = ncol

    def window(self, xmin: float, xmax: float) -> slice:
        """Slice of the points whose column overlaps ``[xmin, xmax]``."""
        c0 = int(np.clip(np.floor(xmin / self.column), 0, self.ncol - 1))
        c1 = int(np.clip(np.floor(xmax / self.column), 0, self.ncol - 1))
        return slice(int(self.offsets[c0]), int(self.offsets[c1 + 1]))
