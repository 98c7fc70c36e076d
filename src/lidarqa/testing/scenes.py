"""Seeded synthetic LiDAR scenes with exactly known truth.

A scene is terrain (slopes, undulation, curbs, embankments), flat-roof and
gable-roof buildings with observed walls, cars, trees, low vegetation and
outliers, sampled like an airborne scan at a given density and noise. Every
scene carries its truth: ground labels, ASPRS classes, object ids, the true
planes, the true 3D edges between pairs of observed adjacent planes and the true
corners where three observed planes meet. Truth is exact (computed from the
construction, not from the points), so detected edges and corners can be scored
to the millimetre.

Conventions
-----------
- Lengths in metres, angles in degrees.
- ``density`` is points per m^2 of *horizontal* area for terrain and roofs (as
  an airborne scanner sees them); walls, curb faces and car sides are sampled at
  ``wall_density`` points per m^2 of their own surface (an oblique or mobile
  view), by default equal to ``density``.
- Noise is Gaussian with standard deviation ``noise`` (m) along the surface
  normal for planar faces (roofs, walls, planar ground) and along z for
  non-planar terrain.
- A plane is ``n . p = rho`` with a unit normal, ``n_z >= 0`` (vertical planes:
  ``n_y >= 0``, then ``n_x >= 0``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from .._validate import as_points, check_choice, check_positive
from ..errors import OptionError
from ..io.pointcloud import PointCloud
from ..io.vector import PointSet, Segments
from ._shapes import CLASS_OTHER, Face, TerrainModel, canonical_plane, polygon_area
from ._world import (
    ROOF_TYPES,
    BuildingSpec,
    _add_shrub,
    _add_structure,
    _add_tree,
    _breaklines,
    _place,
    _plane_normal,
    _random_building,
    _random_terrain,
    _sample_strip,
    _World,
)

PATTERNS = ("random", "jittered")

__all__ = [
    "Scene",
    "TruePlane",
    "BuildingSpec",
    "TerrainModel",
    "make_scene",
    "make_building_scene",
    "make_terrain_scene",
    "rigid_motion",
    "rotation_matrix",
    "sample_checkpoints",
    "plane_area",
    "make_plane_pair",
    "make_corner",
]

# --------------------------------------------------------------------- results


@dataclass(frozen=True, eq=False)
class TruePlane:
    """A true plane of a scene: ``normal . p = rho``.

    Attributes
    ----------
    normal : ndarray of shape (3,)
        Unit normal, ``n_z >= 0`` (vertical planes: ``n_y >= 0``, then ``n_x >= 0``).
    rho : float
        Signed distance of the plane from the coordinate origin (m).
    kind : str
        ``"ground"``, ``"roof"``, ``"wall"``, ``"car_top"`` or ``"car_side"``.
    object_id : int
        Object the plane belongs to (-1 for the ground).
    polygon : ndarray of shape (k, 3) or None
        Outline of the sampled face (None for the ground).
    n_points : int
        Number of scene points sampled on the plane (all strips).
    """

    normal: np.ndarray
    rho: float
    kind: str
    object_id: int = -1
    polygon: np.ndarray | None = None
    n_points: int = 0

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed orthogonal distance (m) of `points` (N, 3) from the plane."""
        return np.asarray(points, dtype=np.float64) @ self.normal - self.rho

    def to_dict(self) -> dict[str, Any]:
        """The result as a dict of plain JSON types (units: ``lidarqa.units``)."""
        return {"normal": [float(v) for v in self.normal], "rho": float(self.rho),
                "kind": self.kind, "object_id": int(self.object_id), "n_points": int(self.n_points)}


@dataclass(frozen=True, eq=False, repr=False)
class Scene:
    """A synthetic point cloud with its exact truth.

    Attributes
    ----------
    points : ndarray of shape (N, 3), float64
        x, y, z (m), in random order.
    classification : ndarray of shape (N,), uint8
        ASPRS codes: 1 other (cars), 2 ground, 3/4/5 low/medium/high vegetation,
        6 building, 7 noise.
    is_ground : ndarray of shape (N,), bool
        True ground label (terrain, curb faces; never under a building or car).
    object_id : ndarray of shape (N,), int64
        Building/car/tree/shrub id, -1 for terrain and outliers.
    plane_id : ndarray of shape (N,), int64
        Index into `planes`, -1 when the point is not on a true plane.
    planes : list of TruePlane
    edges : lidarqa.io.vector.Segments
        True 3D edges where two observed, adjacent planes meet. Attributes:
        ``plane_a < plane_b`` (int64), ``kind`` (``"ridge"``, ``"eave"``,
        ``"verge"``, ``"wall"``, ``"foot"``, ``"car"``), ``object_id``.
    corners : lidarqa.io.vector.PointSet
        True points where three observed planes meet. Attributes: ``plane_a <
        plane_b < plane_c``, ``kind`` (``"ridge"``, ``"eave"``, ``"foot"``,
        ``"car"``), ``object_id``.
    params : dict
        Every generation parameter and the drawn objects (JSON-able).
    fields : dict of str to ndarray of shape (N,)
        Extra per-point dimensions: ``point_source_id`` (uint16, strip number),
        ``return_number`` and ``number_of_returns`` (uint8).
    terrain : TerrainModel or None
        The bare-earth surface (``scene.ground_z(xy)``); None after a rigid
        motion that tilts the scene.
    """

    points: np.ndarray
    classification: np.ndarray
    is_ground: np.ndarray
    object_id: np.ndarray
    plane_id: np.ndarray
    planes: list[TruePlane]
    edges: Segments
    corners: PointSet
    params: dict[str, Any] = field(default_factory=dict)
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    terrain: TerrainModel | None = None

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def __repr__(self) -> str:
        return (f"Scene(n_points={len(self)}, planes={len(self.planes)}, edges={len(self.edges)}, "
                f"corners={len(self.corners)}, maker={self.params.get('maker')!r}, "
                f"seed={self.params.get('seed')!r})")

    @property
    def n_points(self) -> int:
        """Number of points."""
        return len(self)

    def ground_z(self, xy: np.ndarray) -> np.ndarray:
        """True bare-earth height (m) at world `xy` (N, 2); NaN if the terrain is unknown."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if self.terrain is None:
            return np.full(len(xy), np.nan)
        return self.terrain.height(xy)

    def breaklines(self) -> Segments:
        """Terrain break lines (curbs, embankment foot and top) clipped to the extent.

        xy are exact; z is the true terrain height at each endpoint (on a curb
        line itself that may be either side of the step). Attribute ``kind``:
        ``"curb"``, ``"embankment_foot"``, ``"embankment_top"``. Empty without a terrain model.
        """
        if self.terrain is None:
            return Segments(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)),
                            {"kind": np.zeros(0, dtype=str)})
        t = self.terrain
        lines = t.breaklines(tuple(self.params["size"]))
        start = np.array([t.rotation @ a for a, _b, _k in lines]).reshape(-1, 2) + t.offset[:2]
        end = np.array([t.rotation @ b for _a, b, _k in lines]).reshape(-1, 2) + t.offset[:2]
        return Segments(
            np.arange(len(lines), dtype=np.int64),
            np.column_stack([start, self.ground_z(start)]),
            np.column_stack([end, self.ground_z(end)]),
            {"kind": np.array([k for *_ab, k in lines], dtype=str).reshape(-1)},
        )

    def to_dict(self) -> dict[str, Any]:
        """Counts and parameters (JSON-able; no per-point arrays)."""
        cls, cnt = np.unique(self.classification, return_counts=True)
        return {
            "n_points": len(self),
            "classes": {str(int(c)): int(n) for c, n in zip(cls, cnt, strict=True)},
            "n_ground": int(self.is_ground.sum()),
            "n_planes": len(self.planes),
            "n_edges": len(self.edges),
            "n_corners": len(self.corners),
            "params": self.params,
        }

    def subset(self, index: Any) -> Scene:
        """The scene restricted to some points (mask or indices); the truth is kept whole."""
        idx = np.asarray(index)
        return replace(
            self,
            points=self.points[idx],
            classification=self.classification[idx],
            is_ground=self.is_ground[idx],
            object_id=self.object_id[idx],
            plane_id=self.plane_id[idx],
            fields={k: v[idx] for k, v in self.fields.items()},
        )

    def to_cloud(self, *, include_truth: bool = False, crs: Any = None) -> PointCloud:
        """The points as a :class:`~lidarqa.io.PointCloud` (writable with :func:`lidarqa.write`).

        Fields: ``classification`` and every entry of :attr:`fields`; with
        `include_truth`, also ``is_ground`` (uint8), ``object_id`` and
        ``plane_id`` (int32), which become LAS extra bytes. `crs` (anything
        :func:`lidarqa.io.crs.parse_crs` accepts, e.g. ``"EPSG:2154"``) is
        attached to the cloud.
        """
        fields: dict[str, np.ndarray] = {"classification": self.classification.astype(np.uint8)}
        fields.update({k: v.copy() for k, v in self.fields.items()})
        if include_truth:
            fields["is_ground"] = self.is_ground.astype(np.uint8)
            fields["object_id"] = self.object_id.astype(np.int32)
            fields["plane_id"] = self.plane_id.astype(np.int32)
        if crs is not None:
            from ..io.crs import parse_crs

            crs = parse_crs(crs)
        return PointCloud(xyz=self.points.copy(), fields=fields, crs=crs)


# --------------------------------------------------------------------- rigid motions


def rotation_matrix(rotation_deg: Sequence[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Rotation matrix ``Rz @ Ry @ Rx`` for angles (rx, ry, rz) in degrees about x, y, z."""
    rx, ry, rz = np.deg2rad(np.asarray(rotation_deg, dtype=np.float64).reshape(3))
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return mz @ my @ mx


def _move_points(p: np.ndarray, rot: np.ndarray, t: np.ndarray) -> np.ndarray:
    return p @ rot.T + t


def _move_scene(scene: Scene, rot: np.ndarray, t: np.ndarray, record: dict | None) -> Scene:
    planes = []
    for pl in scene.planes:
        n = rot @ pl.normal
        n, rho = canonical_plane(n, pl.rho + float(n @ t))
        poly = None if pl.polygon is None else _move_points(pl.polygon, rot, t)
        planes.append(replace(pl, normal=n, rho=rho, polygon=poly))
    e = scene.edges
    edges = Segments(e.ids, _move_points(e.start, rot, t), _move_points(e.end, rot, t),
                     dict(e.attributes), e.crs)
    c = scene.corners
    corners = PointSet(c.ids, _move_points(c.xyz, rot, t), dict(c.attributes), c.crs)
    terrain = None
    if scene.terrain is not None and np.allclose(rot[2], [0, 0, 1], atol=0, rtol=0):
        terrain = scene.terrain.moved(rot[:2, :2], t)
    params = dict(scene.params)
    if record is not None:
        params["motions"] = [*params.get("motions", []), record]
    return replace(scene, points=_move_points(scene.points, rot, t), planes=planes, edges=edges,
                   corners=corners, terrain=terrain, params=params)


def rigid_motion(
    scene_or_points: Any,
    rotation_deg: Sequence[float] = (0.0, 0.0, 0.0),
    translation: Sequence[float] = (0.0, 0.0, 0.0),
    *,
    center: Sequence[float] | None = None,
) -> Any:
    """Rotate then translate a scene (points AND truth) or an (N, 3) array.

    ``p' = R (p - c) + c + t`` with ``R = Rz @ Ry @ Rx`` from `rotation_deg`
    (degrees about x, y, z), `center` ``c`` (default the coordinate origin) and
    `translation` ``t`` (m).

    Parameters
    ----------
    scene_or_points : Scene, ndarray of shape (N, 3), Segments or PointSet
    rotation_deg : (float, float, float)
    translation : (float, float, float)
    center : (float, float, float), optional

    Returns
    -------
    Same type as the input. A scene keeps planes (normals canonicalised,
    ``n_z >= 0``), edges and corners consistent; its terrain model survives
    rotations about z only.
    """
    rot = rotation_matrix(rotation_deg)
    t = np.asarray(translation, dtype=np.float64).reshape(3)
    if center is not None:
        c = np.asarray(center, dtype=np.float64).reshape(3)
        t = c + t - rot @ c
    if isinstance(scene_or_points, Scene):
        record = {"rotation_deg": [float(v) for v in rotation_deg],
                  "translation": [float(v) for v in translation],
                  "center": None if center is None else [float(v) for v in center]}
        return _move_scene(scene_or_points, rot, t, record)
    if isinstance(scene_or_points, Segments):
        s = scene_or_points
        return Segments(s.ids, _move_points(s.start, rot, t), _move_points(s.end, rot, t),
                        dict(s.attributes), s.crs)
    if isinstance(scene_or_points, PointSet):
        ps = scene_or_points
        return PointSet(ps.ids, _move_points(ps.xyz, rot, t), dict(ps.attributes), ps.crs)
    pts = as_points(scene_or_points)
    return _move_points(pts, rot, t)


def _finish(world: _World, rng: np.random.Generator, *, density: float, noise: float,
            wall_density: float, outliers: int, returns: bool, strips: int, pattern: str,
            strip_offset: Sequence[float], origin: Sequence[float], min_plane_points: int,
            params: dict[str, Any]) -> Scene:
    parts = []
    for k in range(strips):
        d = _sample_strip(world, rng, density=density, noise=noise, wall_density=wall_density,
                          outliers=outliers, returns=returns, pattern=pattern)
        if k >= 1:
            d["xyz"] = d["xyz"] + np.asarray(strip_offset, dtype=np.float64) * k
        d["psid"] = np.full(len(d["xyz"]), k + 1, dtype=np.uint16)
        parts.append(d)
    data = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    order = rng.permutation(len(data["xyz"]))
    data = {key: np.take(v, order, axis=0) for key, v in data.items()}  # take: fast for 2D

    counts = np.bincount(data["pid"][data["pid"] >= 0], minlength=len(world.planes))
    observed = counts >= min_plane_points
    planes = [TruePlane(normal=p["normal"], rho=p["rho"], kind=p["kind"], object_id=p["object_id"],
                        polygon=p["polygon"], n_points=int(counts[i]))
              for i, p in enumerate(world.planes)]

    edges = [e for e in world.edges if observed[e[2]] and observed[e[3]]
             and np.linalg.norm(np.asarray(e[1]) - np.asarray(e[0])) > 1e-9]
    starts = np.array([e[0] for e in edges], dtype=np.float64).reshape(-1, 3)
    ends = np.array([e[1] for e in edges], dtype=np.float64).reshape(-1, 3)
    pa = np.array([min(e[2], e[3]) for e in edges], dtype=np.int64)
    pb = np.array([max(e[2], e[3]) for e in edges], dtype=np.int64)
    seg = Segments(
        ids=np.arange(len(edges), dtype=np.int64), start=starts, end=ends,
        attributes={"plane_a": pa, "plane_b": pb,
                    "kind": np.array([e[4] for e in edges], dtype=str).reshape(-1),
                    "object_id": np.array([e[5] for e in edges], dtype=np.int64)},
    )
    corners = [c for c in world.corners if all(observed[i] for i in c[1])]
    cid = np.array([sorted(c[1]) for c in corners], dtype=np.int64).reshape(-1, 3)
    cps = PointSet(
        ids=np.arange(len(corners), dtype=np.int64),
        xyz=np.array([c[0] for c in corners], dtype=np.float64).reshape(-1, 3),
        attributes={"plane_a": cid[:, 0], "plane_b": cid[:, 1], "plane_c": cid[:, 2],
                    "kind": np.array([c[2] for c in corners], dtype=str).reshape(-1),
                    "object_id": np.array([c[3] for c in corners], dtype=np.int64)},
    )
    fields = {"point_source_id": data["psid"]}
    if returns:
        fields["return_number"] = data["ret"]
        fields["number_of_returns"] = data["nret"]
    scene = Scene(
        points=data["xyz"],
        classification=data["cls"],
        is_ground=data["ground"],
        object_id=data["oid"],
        plane_id=data["pid"],
        planes=planes,
        edges=seg,
        corners=cps,
        params=params,
        fields=fields,
        terrain=world.terrain,
    )
    o = np.asarray(origin, dtype=np.float64).reshape(3)
    if np.any(o != 0):
        scene = _move_scene(scene, np.eye(3), o, None)
    return scene


def _check_common(density: float, noise: float, wall_density: float | None, strips: int,
                  min_plane_points: int) -> float:
    check_positive(density, "density")
    check_positive(noise, "noise", allow_zero=True)
    wd = density if wall_density is None else check_positive(wall_density, "wall_density",
                                                             allow_zero=True)
    if int(strips) != strips or strips < 1:
        raise OptionError(f"strips must be an integer >= 1, got {strips!r}")
    if int(min_plane_points) != min_plane_points or min_plane_points < 1:
        raise OptionError(f"min_plane_points must be an integer >= 1, got {min_plane_points!r}")
    return float(wd)


def _check_size(size: Any) -> tuple[float, float]:
    try:
        w, h = (float(v) for v in size)
    except (TypeError, ValueError) as exc:
        raise OptionError(f"size must be (width, height) in metres, got {size!r}") from exc
    check_positive(w, "size[0]")
    check_positive(h, "size[1]")
    return w, h


# --------------------------------------------------------------------- public makers


def make_scene(
    *,
    seed: int = 0,
    size: tuple[float, float] = (100.0, 100.0),
    density: float = 20.0,
    noise: float = 0.02,
    wall_density: float | None = None,
    roofs: Sequence[str] = ("flat", "gable"),
    n_buildings: int | None = None,
    n_cars: int | None = None,
    n_trees: int | None = None,
    n_shrubs: int | None = None,
    slope_deg: float = 3.0,
    undulation: float = 0.3,
    curbs: int = 1,
    curb_height: float | None = None,
    embankment: bool | float = False,
    outliers: int | None = None,
    returns: bool = False,
    strips: int = 1,
    strip_offset: Sequence[float] = (0.0, 0.0, 0.0),
    origin: Sequence[float] = (0.0, 0.0, 0.0),
    foot_edges: bool = True,
    min_plane_points: int = 10,
    overhang: float = 0.0,
    pattern: str = "random",
) -> Scene:
    """A full synthetic scene: terrain, buildings, cars, trees, shrubs, outliers.

    Parameters
    ----------
    seed : int
        Seed of ``numpy.random.default_rng``; the same seed gives the same scene.
    size : (float, float), default (100, 100)
        Extent in x and y (m). About ``density * area`` terrain points: ``(316, 316)``
        gives ~2 M points at 20 pts/m^2.
    density : float, default 20
        Points per m^2 of horizontal area on terrain and roofs.
    noise : float, default 0.02
        Standard deviation (m) of the Gaussian point noise (along the surface normal).
    wall_density : float, optional
        Points per m^2 of wall (and car side, curb face) surface; default `density`.
    roofs : sequence of {"flat", "gable"}
        Roof types drawn (cyclically) for the buildings.
    n_buildings, n_cars, n_trees, n_shrubs : int, optional
        Object counts; by default 4, 8, 20 and 10 per hectare. Objects never
        overlap each other nor cross a break line; fewer are placed if they
        do not fit (see ``params["counts"]``).
    slope_deg : float, default 3
        Planar tilt of the terrain (degrees), in a random direction.
    undulation : float, default 0.3
        Total amplitude (m) of three long-wave sinusoids (wavelength 30-120 m).
    curbs : int, default 1
        Number of roads; each has two curbs (ground outside the road raised by
        `curb_height`).
    curb_height : float, optional
        Step height (m); default random in 0.15-0.3 m.
    embankment : bool or float, default False
        Add a steep ramp (1.5-3 m wide) of random 2-4 m height (or this height, m).
    outliers : int, optional
        Number of noise points (class 7), half 1-15 m below the ground, half
        20-80 m above; default 2 per hectare.
    returns : bool, default False
        Add ``return_number``/``number_of_returns``: 60 % of crown points are first
        of two returns, the second on the ground beneath.
    strips : int, default 1
        Number of overlapping flight strips, each sampled independently over the
        whole extent at `density` (``fields["point_source_id"]`` = 1, 2, ...).
    strip_offset : (float, float, float)
        Systematic shift (m) of strip k+1 is ``k * strip_offset``; truth is strip 1's.
    origin : (float, float, float)
        Translation of the whole scene, points and truth (e.g. ``(500000, 5400000, 100)``).
    foot_edges : bool, default True
        Include wall-ground edges and corners when the ground is a plane.
    min_plane_points : int, default 10
        A plane with fewer points is unobserved: no edge or corner uses it.
    overhang : float, default 0
        Roof overhang (m) of every building (see :class:`BuildingSpec`).
    pattern : {"random", "jittered"}, default "random"
        Point layout on terrain, roofs and walls: independent uniform points
        (Poisson counts), or one uniform point per cell of a randomly shifted
        grid with cell area 1/density (even spacing, like a scanner; counts
        fixed by the area). Trees, shrubs and curb faces are always random.

    Returns
    -------
    Scene
    """
    size = _check_size(size)
    wd = _check_common(density, noise, wall_density, strips, min_plane_points)
    check_choice(pattern, PATTERNS, "pattern")
    for r in roofs:
        check_choice(r, ROOF_TYPES, "roofs")
    rng = np.random.default_rng(seed)
    ha = size[0] * size[1] / 1e4
    n_buildings = round(4 * ha) if n_buildings is None else int(n_buildings)
    n_cars = round(8 * ha) if n_cars is None else int(n_cars)
    n_trees = round(20 * ha) if n_trees is None else int(n_trees)
    n_shrubs = round(10 * ha) if n_shrubs is None else int(n_shrubs)
    outliers = round(2 * ha) if outliers is None else int(outliers)
    if not roofs and n_buildings:
        raise OptionError("roofs must name at least one roof type when there are buildings")
    terrain = _random_terrain(rng, size, slope_deg=slope_deg, undulation=undulation, curbs=curbs,
                              curb_height=curb_height, embankment=embankment)
    world = _World(size=size, terrain=terrain)
    if terrain.is_planar:
        n, rho = terrain.plane()
        world.ground_plane = world.add_plane(n, n * rho, "ground", -1, None)
    occupied: list = []
    keepout = _breaklines(terrain)
    buildings: list[BuildingSpec] = []
    drafts = [replace(_random_building(rng, roofs[i % len(roofs)], np.zeros(2)), overhang=overhang)
              for i in range(n_buildings)]
    for spec in drafts:
        got = _place(rng, 1, lambda s=spec: s.radius, size, occupied, keepout)
        if got:
            buildings.append(replace(spec, center=(float(got[0][0][0]), float(got[0][0][1]))))
    for spec in buildings:
        _add_structure(world, spec, object_kind="building", density=density, wall_density=wd,
                       foot_edges=foot_edges)
    cars = []
    for _ in range(n_cars):
        spec = BuildingSpec("flat", (0.0, 0.0), float(rng.uniform(4.2, 4.9)),
                            float(rng.uniform(1.7, 1.9)), float(rng.uniform(0, 180)),
                            float(rng.uniform(1.4, 1.6)))
        got = _place(rng, 1, lambda s=spec: s.radius, size, occupied, keepout)
        if got:
            spec = replace(spec, center=(float(got[0][0][0]), float(got[0][0][1])))
            cars.append(spec)
            _add_structure(world, spec, object_kind="car", density=density, wall_density=wd,
                           foot_edges=foot_edges)
    for c, r in _place(rng, n_trees, lambda: rng.uniform(1.5, 4.0), size, occupied, []):
        _add_tree(world, rng, c, r)
    for c, _r in _place(rng, n_shrubs, lambda: 1.5, size, occupied, []):
        _add_shrub(world, rng, c)
    params = {
        "maker": "make_scene", "seed": seed, "size": list(size), "density": density,
        "noise": noise, "wall_density": wd, "roofs": list(roofs), "slope_deg": slope_deg,
        "undulation": undulation, "curbs": curbs, "curb_height": curb_height,
        "embankment": embankment, "outliers": outliers, "returns": returns, "strips": strips,
        "strip_offset": [float(v) for v in strip_offset], "origin": [float(v) for v in origin],
        "foot_edges": foot_edges, "min_plane_points": min_plane_points, "overhang": overhang,
        "pattern": pattern,
        "counts": {"buildings": len(buildings), "cars": len(cars), "trees": len(world.trees),
                   "shrubs": len(world.shrubs)},
        "buildings": [asdict(b) for b in buildings],
        "cars": [asdict(c) for c in cars],
    }
    return _finish(world, rng, density=density, noise=noise, wall_density=wd, outliers=outliers,
                   returns=returns, strips=strips, pattern=pattern,
                   strip_offset=strip_offset, origin=origin,
                   min_plane_points=min_plane_points, params=params)


def make_terrain_scene(
    *,
    seed: int = 0,
    size: tuple[float, float] = (100.0, 100.0),
    density: float = 20.0,
    noise: float = 0.02,
    slope_deg: float = 5.0,
    undulation: float = 0.5,
    curbs: int = 1,
    curb_height: float | None = None,
    embankment: bool | float = True,
    n_buildings: int = 0,
    n_cars: int = 0,
    n_trees: int = 0,
    n_shrubs: int = 0,
    outliers: int = 0,
    **kwargs: Any,
) -> Scene:
    """Bare terrain with slope, undulation, curbs and an embankment (objects optional).

    Same parameters as :func:`make_scene` (other keywords are passed on), with
    terrain-focused defaults: no objects, no outliers, 5 degree slope, 0.5 m
    undulation, one road with curbs and one embankment. The true surface is
    ``scene.ground_z(xy)``.
    """
    scene = make_scene(seed=seed, size=size, density=density, noise=noise, slope_deg=slope_deg,
                       undulation=undulation, curbs=curbs, curb_height=curb_height,
                       embankment=embankment, n_buildings=n_buildings, n_cars=n_cars,
                       n_trees=n_trees, n_shrubs=n_shrubs, outliers=outliers, **kwargs)
    scene.params["maker"] = "make_terrain_scene"
    return scene


def make_building_scene(
    *,
    seed: int = 0,
    roofs: Sequence[str] = ("flat", "gable"),
    density: float = 20.0,
    noise: float = 0.02,
    wall_density: float | None = None,
    buildings: Sequence[BuildingSpec] | None = None,
    spacing: float = 40.0,
    slope_deg: float = 0.0,
    ground: bool = True,
    foot_edges: bool = True,
    strips: int = 1,
    strip_offset: Sequence[float] = (0.0, 0.0, 0.0),
    origin: Sequence[float] = (0.0, 0.0, 0.0),
    min_plane_points: int = 10,
    overhang: float = 0.0,
    pattern: str = "random",
) -> Scene:
    """Buildings with observed walls on a planar ground: one building per roof type in `roofs`.

    Parameters
    ----------
    seed : int
    roofs : sequence of {"flat", "gable"}, default ("flat", "gable")
        One random building per entry (e.g. ``("gable",) * 6``), laid out on a
        grid of `spacing` x `spacing` cells with random size, orientation,
        height and pitch (flat: 10-20 x 7-14 m, 4-12 m high; gable: 10-18 x
        7-11 m, eaves 3-7 m, pitch 25-45 degrees).
    density, noise, wall_density : float
        As in :func:`make_scene`.
    buildings : sequence of BuildingSpec, optional
        Exact buildings (local coordinates) instead of random ones; the extent
        then covers them with a 10 m margin (from 0, 0).
    spacing : float, default 40
        Grid cell size (m) for random buildings.
    slope_deg : float, default 0
        Tilt of the ground plane (degrees). Walls rise from the tilted ground.
    ground : bool, default True
        Sample the ground plane (plane 0). Without it there are no foot edges.
    foot_edges : bool, default True
        Include wall-ground edges (kind ``"foot"``) and their corners.
    strips, strip_offset, origin, min_plane_points
        As in :func:`make_scene`.
    overhang : float, default 0
        Roof overhang (m) of the random buildings (see :class:`BuildingSpec`).
    pattern : {"random", "jittered"}, default "random"
        As in :func:`make_scene`.

    Returns
    -------
    Scene
        Edge kinds ``ridge``, ``eave``, ``verge``, ``wall``, ``foot``; corner kinds
        ``ridge``, ``eave``, ``foot``.
    """
    wd = _check_common(density, noise, wall_density, strips, min_plane_points)
    check_choice(pattern, PATTERNS, "pattern")
    rng = np.random.default_rng(seed)
    if buildings is None:
        for r in roofs:
            check_choice(r, ROOF_TYPES, "roofs")
        nb = len(roofs)
        if nb == 0:
            raise OptionError("roofs must name at least one roof type")
        cols = int(np.ceil(np.sqrt(nb)))
        rows = int(np.ceil(nb / cols))
        size = (cols * float(spacing), rows * float(spacing))
        specs = []
        for i, roof in enumerate(roofs):
            cx = (i % cols + 0.5) * spacing
            cy = (i // cols + 0.5) * spacing
            spec = replace(_random_building(rng, roof, np.zeros(2)), overhang=overhang)
            room = 0.5 * spacing - spec.radius - 1.0
            jitter = rng.uniform(-1, 1, 2) * max(room, 0.0)
            specs.append(replace(spec, center=(float(cx + jitter[0]), float(cy + jitter[1]))))
    else:
        specs = [b if isinstance(b, BuildingSpec) else BuildingSpec(**b) for b in buildings]
        if specs:
            xmax = max(b.center[0] + b.radius for b in specs) + 10.0
            ymax = max(b.center[1] + b.radius for b in specs) + 10.0
        else:
            xmax = ymax = 20.0
        size = (float(xmax), float(ymax))
    az = rng.uniform(0, 2 * np.pi)
    g = np.tan(np.deg2rad(slope_deg))
    terrain = TerrainModel(z0=0.0, gx=float(g * np.cos(az)), gy=float(g * np.sin(az)))
    world = _World(size=size, terrain=terrain, ground=bool(ground))
    if ground:
        n, rho = terrain.plane()
        world.ground_plane = world.add_plane(n, n * rho, "ground", -1, None)
    for spec in specs:
        _add_structure(world, spec, object_kind="building", density=density, wall_density=wd,
                       foot_edges=foot_edges)
    params = {
        "maker": "make_building_scene", "seed": seed, "size": list(size), "density": density,
        "noise": noise, "wall_density": wd, "roofs": [b.roof for b in specs],
        "spacing": spacing, "overhang": overhang, "slope_deg": slope_deg, "ground": ground,
        "foot_edges": foot_edges, "pattern": pattern,
        "strips": strips, "strip_offset": [float(v) for v in strip_offset],
        "origin": [float(v) for v in origin], "min_plane_points": min_plane_points,
        "counts": {"buildings": len(specs)},
        "buildings": [asdict(b) for b in specs],
    }
    return _finish(world, rng, density=density, noise=noise, wall_density=wd, outliers=0,
                   returns=False, strips=strips, pattern=pattern,
                   strip_offset=strip_offset, origin=origin,
                   min_plane_points=min_plane_points, params=params)


def _small_scene(faces: list[np.ndarray], kinds: list[str], edges: list[tuple],
                 corners: list[tuple], *, maker: str, seed: int, density: float, noise: float,
                 rotation_deg: Sequence[float], translation: Sequence[float],
                 params: dict[str, Any]) -> Scene:
    check_positive(density, "density")
    check_positive(noise, "noise", allow_zero=True)
    rng = np.random.default_rng(seed)
    world = _World(size=(1.0, 1.0), terrain=TerrainModel(), ground=False)
    for poly, kind in zip(faces, kinds, strict=True):
        pid = world.add_plane(_plane_normal(poly), poly[0], kind, 0, poly)
        world.faces.append(Face(poly, pid, CLASS_OTHER, 0, density))
    world.edges.extend(edges)
    world.corners.extend(corners)
    params = {"maker": maker, "seed": seed, "density": density, "noise": noise,
              "rotation_deg": [float(v) for v in rotation_deg],
              "translation": [float(v) for v in translation], "size": [1.0, 1.0], **params}
    scene = _finish(world, rng, density=density, noise=noise, wall_density=density, outliers=0,
                    returns=False, strips=1, pattern="random", strip_offset=(0.0, 0.0, 0.0),
                    origin=(0.0, 0.0, 0.0), min_plane_points=3, params=params)
    scene = _move_scene(scene, rotation_matrix(rotation_deg),
                        np.asarray(translation, dtype=np.float64).reshape(3), None)
    return replace(scene, terrain=None)


def make_plane_pair(
    *,
    angle_deg: float = 90.0,
    length: float = 10.0,
    width: float = 5.0,
    density: float = 20.0,
    noise: float = 0.02,
    seed: int = 0,
    rotation_deg: Sequence[float] = (0.0, 0.0, 0.0),
    translation: Sequence[float] = (0.0, 0.0, 0.0),
) -> Scene:
    """Two planar strips meeting along one edge at a given dihedral angle.

    Before the motion, strip A is ``z = 0, -width <= y <= 0`` and strip B leaves
    the edge ``(0, 0, 0)-(length, 0, 0)`` in direction
    ``(0, -cos(angle), sin(angle))``: 90 degrees is a floor and a wall, 180
    coplanar, small angles a sharp wedge.

    Parameters
    ----------
    angle_deg : float, default 90
        Interior angle between the strips (degrees, 0 < angle < 180).
    length, width : float
        Edge length and strip width (m).
    density : float
        Points per m^2 of each strip.
    noise : float
        Gaussian noise (m) along each plane's normal.
    seed : int
    rotation_deg, translation
        A rigid motion applied to points and truth (see :func:`rigid_motion`).

    Returns
    -------
    Scene
        planes 0 and 1 (kind ``"strip"``), one edge (kind ``"pair"``), no corners;
        ``classification`` 1.
    """
    if not 0.0 < float(angle_deg) < 180.0:
        raise OptionError(f"angle_deg must be in (0, 180) degrees, got {angle_deg!r}")
    check_positive(length, "length")
    check_positive(width, "width")
    a = np.deg2rad(angle_deg)
    d = np.array([0.0, -np.cos(a), np.sin(a)]) * width
    o, e = np.zeros(3), np.array([length, 0.0, 0.0])
    face_a = np.array([o, e, e + [0, -width, 0], o + [0, -width, 0]])
    face_b = np.array([o, e, e + d, o + d])
    return _small_scene([face_a, face_b], ["strip", "strip"], [(o, e, 0, 1, "pair", 0)], [],
                        maker="make_plane_pair", seed=seed, density=density, noise=noise,
                        rotation_deg=rotation_deg, translation=translation,
                        params={"angle_deg": angle_deg, "length": length, "width": width})


def make_corner(
    *,
    size: float = 5.0,
    density: float = 20.0,
    noise: float = 0.02,
    seed: int = 0,
    rotation_deg: Sequence[float] = (0.0, 0.0, 0.0),
    translation: Sequence[float] = (0.0, 0.0, 0.0),
) -> Scene:
    """Three mutually orthogonal square faces meeting at one corner (a box corner).

    Before the motion the faces are ``z = 0``, ``x = 0`` and ``y = 0`` (each
    `size` x `size` m in the positive octant) and the corner is the origin.

    Returns
    -------
    Scene
        planes 0-2 (kind ``"face"``), three edges (kind ``"pair"``) and one corner
        (kind ``"corner"``).
    """
    check_positive(size, "size")
    s = float(size)
    o = np.zeros(3)
    ex, ey, ez = np.array([s, 0, 0.0]), np.array([0, s, 0.0]), np.array([0, 0, s])
    floor = np.array([o, ex, ex + ey, ey])
    wall_x0 = np.array([o, ey, ey + ez, ez])
    wall_y0 = np.array([o, ez, ez + ex, ex])
    edges = [(o, ey, 0, 1, "pair", 0), (o, ex, 0, 2, "pair", 0), (o, ez, 1, 2, "pair", 0)]
    return _small_scene([floor, wall_x0, wall_y0], ["face"] * 3, edges,
                        [(o, (0, 1, 2), "corner", 0)], maker="make_corner", seed=seed,
                        density=density, noise=noise, rotation_deg=rotation_deg,
                        translation=translation, params={"face_size": s})


def plane_area(plane: TruePlane) -> float:
    """Area (m^2) of a plane's sampled face (NaN for the ground)."""
    return float("nan") if plane.polygon is None else polygon_area(plane.polygon)


def sample_checkpoints(
    scene: Scene,
    n: int = 100,
    *,
    seed: int = 0,
    clearance: float = 2.0,
    max_curvature: float = 0.01,
) -> PointSet:
    """True bare-earth check points at random open places of a scene.

    A place qualifies when no non-ground point of the scene lies within
    `clearance` (m, horizontally) and the terrain is locally planar there (no
    curb or embankment within `clearance`: second differences of the true
    surface over +-`clearance` along x, y and both diagonals below
    `max_curvature` m).

    Parameters
    ----------
    scene : Scene
        A scene with a terrain model (not tilted by :func:`rigid_motion`).
    n : int, default 100
        Number of check points wanted; fewer are returned if the open area is small.
    seed : int, default 0
    clearance : float, default 2.0
    max_curvature : float, default 0.01

    Returns
    -------
    PointSet
        ids ``CP0001``... and exact xyz (z = ``scene.ground_z(xy)``, no noise).
    """
    from scipy.spatial import cKDTree

    if scene.terrain is None:
        raise OptionError("sample_checkpoints needs a scene with a terrain model (not tilted)")
    check_positive(clearance, "clearance")
    rng = np.random.default_rng(seed)
    g = scene.is_ground
    gxy = scene.points[g, :2]
    if len(gxy) == 0 or n <= 0:
        return PointSet(np.zeros(0, dtype=str), np.zeros((0, 3)))
    lo, hi = gxy.min(axis=0) + clearance, gxy.max(axis=0) - clearance
    cand = lo + rng.random((20 * n, 2)) * np.maximum(hi - lo, 0.0)
    other = scene.points[~g, :2]
    if len(other):
        d, _ = cKDTree(other).query(cand, k=1, distance_upper_bound=clearance)
        cand = cand[~np.isfinite(d)]
    z0 = scene.ground_z(cand)
    ok = np.ones(len(cand), dtype=bool)
    for dx, dy in ((1, 0), (0, 1), (0.7071067811865476, 0.7071067811865476),
                   (0.7071067811865476, -0.7071067811865476)):
        step = clearance * np.array([dx, dy])
        second = scene.ground_z(cand + step) + scene.ground_z(cand - step) - 2 * z0
        ok &= np.abs(second) <= max_curvature
    # ground points must surround the place (not a hole under an object)
    d, _ = cKDTree(gxy).query(cand, k=1)
    ok &= d < clearance
    cand, z0 = cand[ok][:n], z0[ok][:n]
    ids = np.array([f"CP{i + 1:04d}" for i in range(len(cand))])
    return PointSet(ids, np.column_stack([cand, z0]))


def roof_points(scene: Any) -> np.ndarray:
    """The building points of a :func:`make_building_scene` scene on its roof planes only.

    Wall points are left out (planes steeper than ~73°), as an airborne scan
    barely sees thin walls: the input of outline and step-edge tests.
    """
    nz = np.array([abs(p.normal[2]) for p in scene.planes])
    pid = scene.plane_id
    keep = (scene.classification == 6) & (pid >= 0) & (nz[np.maximum(pid, 0)] > 0.3)
    return scene.points[keep]
