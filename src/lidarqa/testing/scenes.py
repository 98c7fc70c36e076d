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
from ._shapes import (
    CLASS_BUILDING,
    CLASS_GROUND,
    CLASS_HIGH_VEG,
    CLASS_LOW_VEG,
    CLASS_MEDIUM_VEG,
    CLASS_NOISE,
    CLASS_OTHER,
    Face,
    TerrainModel,
    _clip_line,
    canonical_plane,
    in_rectangle,
    polygon_area,
    rect_corners,
    sample_polygon,
    x_window,
)

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
]

ROOF_TYPES = ("flat", "gable")


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
        return {"normal": [float(v) for v in self.normal], "rho": float(self.rho),
                "kind": self.kind, "object_id": int(self.object_id), "n_points": int(self.n_points)}


@dataclass(frozen=True)
class BuildingSpec:
    """One building of a scene.

    Parameters
    ----------
    roof : {"flat", "gable"}
    center : (float, float)
        Footprint centre in the scene's local frame (m; the extent starts at 0, 0).
    length, width : float
        Footprint size (m); a gable ridge runs along `length`.
    azimuth_deg : float
        Direction of the `length` axis, counter-clockwise from +x (degrees).
    height : float
        Eave height (flat roof: roof height) above the highest footprint corner's ground (m).
    pitch_deg : float
        Gable roof pitch (degrees, 0 < pitch < 90); ignored for flat roofs.
    """

    roof: str = "flat"
    center: tuple[float, float] = (20.0, 20.0)
    length: float = 15.0
    width: float = 10.0
    azimuth_deg: float = 0.0
    height: float = 6.0
    pitch_deg: float = 35.0

    def __post_init__(self) -> None:
        check_choice(self.roof, ROOF_TYPES, "roof")
        check_positive(self.length, "length")
        check_positive(self.width, "width")
        check_positive(self.height, "height")
        if self.roof == "gable" and not 0.0 < float(self.pitch_deg) < 90.0:
            raise OptionError(f"pitch_deg must be in (0, 90) degrees, got {self.pitch_deg!r}")

    @property
    def radius(self) -> float:
        return 0.5 * float(np.hypot(self.length, self.width))


@dataclass(frozen=True, eq=False)
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

    def to_cloud(self, *, include_truth: bool = False) -> PointCloud:
        """The points as a :class:`~lidarqa.io.PointCloud` (writable with :func:`lidarqa.write`).

        Fields: ``classification`` and every entry of :attr:`fields`; with
        `include_truth`, also ``is_ground`` (uint8), ``object_id`` and
        ``plane_id`` (int32), which become LAS extra bytes.
        """
        fields: dict[str, np.ndarray] = {"classification": self.classification.astype(np.uint8)}
        fields.update({k: v.copy() for k, v in self.fields.items()})
        if include_truth:
            fields["is_ground"] = self.is_ground.astype(np.uint8)
            fields["object_id"] = self.object_id.astype(np.int32)
            fields["plane_id"] = self.plane_id.astype(np.int32)
        return PointCloud(xyz=self.points.copy(), fields=fields)


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
        s = scene_or_points
        return PointSet(s.ids, _move_points(s.xyz, rot, t), dict(s.attributes), s.crs)
    pts = as_points(scene_or_points)
    return _move_points(pts, rot, t)


# --------------------------------------------------------------------- world construction


@dataclass
class _World:
    """Noise-free geometry in the local frame, before sampling."""

    size: tuple[float, float]
    terrain: TerrainModel
    ground: bool = True
    planes: list[dict] = field(default_factory=list)
    faces: list[Face] = field(default_factory=list)
    edges: list[tuple] = field(default_factory=list)
    corners: list[tuple] = field(default_factory=list)
    footprints: list[tuple] = field(default_factory=list)  # (center, L, W, az)
    trees: list[dict] = field(default_factory=list)
    shrubs: list[dict] = field(default_factory=list)
    ground_plane: int = -1
    next_object: int = 0

    def add_plane(self, normal: np.ndarray, point: np.ndarray, kind: str, object_id: int,
                  polygon: np.ndarray | None) -> int:
        n, rho = canonical_plane(normal, float(np.dot(normal, point)))
        self.planes.append({"normal": n, "rho": rho, "kind": kind, "object_id": object_id,
                            "polygon": polygon})
        return len(self.planes) - 1

    def new_object(self) -> int:
        self.next_object += 1
        return self.next_object - 1


def _plane_normal(vertices: np.ndarray) -> np.ndarray:
    """Newell normal of a planar polygon (exact up to rounding)."""
    v = vertices
    w = np.roll(v, -1, axis=0)
    n = np.array([
        np.sum((v[:, 1] - w[:, 1]) * (v[:, 2] + w[:, 2])),
        np.sum((v[:, 2] - w[:, 2]) * (v[:, 0] + w[:, 0])),
        np.sum((v[:, 0] - w[:, 0]) * (v[:, 1] + w[:, 1])),
    ])
    return n / np.linalg.norm(n)


def _add_structure(world: _World, spec: BuildingSpec, *, object_kind: str, density: float,
                   wall_density: float, foot_edges: bool) -> int:
    """Add a building ("building") or a car ("car") with its planes, faces, edges, corners."""
    oid = world.new_object()
    is_car = object_kind == "car"
    cls = CLASS_OTHER if is_car else CLASS_BUILDING
    roof_kind, wall_kind = ("car_top", "car_side") if is_car else ("roof", "wall")
    planar = world.terrain.is_planar
    c2 = rect_corners(np.asarray(spec.center, dtype=np.float64), spec.length, spec.width,
                      spec.azimuth_deg)
    g = world.terrain.local_height(c2)
    top = (g.min() if is_car else g.max()) + spec.height
    bottom = g if planar else np.full(4, g.min() - 1.0)
    world.footprints.append((np.asarray(spec.center, float), spec.length, spec.width,
                             spec.azimuth_deg))

    def p3(xy: np.ndarray, z: float) -> np.ndarray:
        return np.array([xy[0], xy[1], z])

    roof_ids: list[int] = []
    if spec.roof == "flat" or is_car:
        poly = np.array([p3(c2[i], top) for i in range(4)])
        rid = world.add_plane(np.array([0.0, 0.0, 1.0]), poly[0], roof_kind, oid, poly)
        world.faces.append(Face(poly, rid, cls, oid, density))
        roof_ids = [rid]
        wall_tops = {i: [p3(c2[i], top), p3(c2[(i + 1) % 4], top)] for i in range(4)}
        ridge = None
    else:
        rise = 0.5 * spec.width * np.tan(np.deg2rad(spec.pitch_deg))
        zr = top + rise
        r0 = 0.5 * (c2[3] + c2[0])
        r1 = 0.5 * (c2[1] + c2[2])
        ridge = (p3(r0, zr), p3(r1, zr))
        face_a = np.array([p3(c2[0], top), p3(c2[1], top), ridge[1], ridge[0]])
        face_b = np.array([p3(c2[2], top), p3(c2[3], top), ridge[0], ridge[1]])
        for poly in (face_a, face_b):
            n = _plane_normal(poly)
            rid = world.add_plane(n, poly[0], roof_kind, oid, poly)
            # airborne density per horizontal m^2 -> per surface m^2
            world.faces.append(Face(poly, rid, cls, oid, density * abs(world.planes[rid]["normal"][2])))
            roof_ids.append(rid)
        wall_tops = {
            0: [p3(c2[0], top), p3(c2[1], top)],
            1: [p3(c2[1], top), ridge[1], p3(c2[2], top)],
            2: [p3(c2[2], top), p3(c2[3], top)],
            3: [p3(c2[3], top), ridge[0], p3(c2[0], top)],
        }

    wall_ids = []
    for i in range(4):
        j = (i + 1) % 4
        e = c2[j] - c2[i]
        n = np.array([e[1], -e[0], 0.0]) / np.hypot(e[0], e[1])  # outward for CCW corners
        tops = wall_tops[i]
        # order: bottom_i, bottom_j, top_j ... top_i (convex)
        poly = np.array([p3(c2[i], bottom[i]), p3(c2[j], bottom[j]), *tops[::-1]])
        wid = world.add_plane(n, poly[0], wall_kind, oid, poly)
        world.faces.append(Face(poly, wid, cls, oid, wall_density, clip_below_terrain=not planar))
        wall_ids.append(wid)

    ek = (lambda k: "car") if is_car else (lambda k: k)
    # eaves (roof - wall), verges, ridge
    if ridge is None:
        r = roof_ids[0]
        for i in range(4):
            a, b = wall_tops[i]
            world.edges.append((a, b, r, wall_ids[i], ek("eave"), oid))
            world.corners.append((a, (r, wall_ids[i - 1], wall_ids[i]), ek("eave"), oid))
    else:
        ra, rb = roof_ids
        world.edges.append((ridge[0], ridge[1], ra, rb, "ridge", oid))
        world.edges.append((*wall_tops[0], ra, wall_ids[0], "eave", oid))
        world.edges.append((*wall_tops[2], rb, wall_ids[2], "eave", oid))
        world.edges.append((p3(c2[1], top), ridge[1], ra, wall_ids[1], "verge", oid))
        world.edges.append((p3(c2[2], top), ridge[1], rb, wall_ids[1], "verge", oid))
        world.edges.append((p3(c2[0], top), ridge[0], ra, wall_ids[3], "verge", oid))
        world.edges.append((p3(c2[3], top), ridge[0], rb, wall_ids[3], "verge", oid))
        world.corners.append((ridge[0], (ra, rb, wall_ids[3]), "ridge", oid))
        world.corners.append((ridge[1], (ra, rb, wall_ids[1]), "ridge", oid))
        world.corners.append((p3(c2[0], top), (ra, wall_ids[0], wall_ids[3]), "eave", oid))
        world.corners.append((p3(c2[1], top), (ra, wall_ids[0], wall_ids[1]), "eave", oid))
        world.corners.append((p3(c2[2], top), (rb, wall_ids[1], wall_ids[2]), "eave", oid))
        world.corners.append((p3(c2[3], top), (rb, wall_ids[2], wall_ids[3]), "eave", oid))
    # vertical wall-wall edges from the ground at the corner up to the eave
    for i in range(4):
        world.edges.append((p3(c2[i], g[i]), p3(c2[i], top), wall_ids[i - 1], wall_ids[i],
                            ek("wall"), oid))
    # foot lines and corners on a planar ground
    if planar and world.ground and world.ground_plane >= 0 and foot_edges:
        gp = world.ground_plane
        for i in range(4):
            j = (i + 1) % 4
            world.edges.append((p3(c2[i], g[i]), p3(c2[j], g[j]), gp, wall_ids[i], ek("foot"), oid))
            world.corners.append((p3(c2[i], g[i]), (gp, wall_ids[i - 1], wall_ids[i]), ek("foot"),
                                  oid))
    return oid


def _add_tree(world: _World, rng: np.random.Generator, center: np.ndarray) -> None:
    oid = world.new_object()
    gz = float(world.terrain.local_height(center[None, :])[0])
    trunk_h = float(rng.uniform(1.5, 4.0))
    crown_rz = float(rng.uniform(1.5, 4.0))
    world.trees.append({
        "object_id": oid, "center": center, "ground_z": gz, "trunk_height": trunk_h,
        "trunk_radius": float(rng.uniform(0.12, 0.3)), "crown_radius": float(rng.uniform(1.5, 4.0)),
        "crown_rz": crown_rz, "crown_z": gz + trunk_h + crown_rz,
    })


def _add_shrub(world: _World, rng: np.random.Generator, center: np.ndarray) -> None:
    oid = world.new_object()
    world.shrubs.append({"object_id": oid, "center": center, "radius": float(rng.uniform(0.5, 2.0)),
                         "height": float(rng.uniform(0.3, 1.5))})


# --------------------------------------------------------------------- sampling


class _Chunks:
    def __init__(self) -> None:
        self.parts: list[dict[str, np.ndarray]] = []

    def add(self, xyz: np.ndarray, cls: Any, ground: Any, oid: Any, pid: Any,
            ret: Any = 1, nret: Any = 1) -> None:
        n = len(xyz)
        if n == 0:
            return
        self.parts.append({
            "xyz": xyz,
            "cls": np.broadcast_to(np.asarray(cls, np.uint8), (n,)),
            "ground": np.broadcast_to(np.asarray(ground, bool), (n,)),
            "oid": np.broadcast_to(np.asarray(oid, np.int64), (n,)),
            "pid": np.broadcast_to(np.asarray(pid, np.int64), (n,)),
            "ret": np.broadcast_to(np.asarray(ret, np.uint8), (n,)),
            "nret": np.broadcast_to(np.asarray(nret, np.uint8), (n,)),
        })

    def concat(self) -> dict[str, np.ndarray]:
        keys = ("xyz", "cls", "ground", "oid", "pid", "ret", "nret")
        if not self.parts:
            empty = {"xyz": np.zeros((0, 3)), "cls": np.zeros(0, np.uint8),
                     "ground": np.zeros(0, bool), "oid": np.zeros(0, np.int64),
                     "pid": np.zeros(0, np.int64), "ret": np.zeros(0, np.uint8),
                     "nret": np.zeros(0, np.uint8)}
            return empty
        return {k: np.concatenate([p[k] for p in self.parts]) for k in keys}


def _veg_class(hag: np.ndarray) -> np.ndarray:
    return np.where(hag > 2.0, CLASS_HIGH_VEG,
                    np.where(hag > 0.5, CLASS_MEDIUM_VEG, CLASS_LOW_VEG)).astype(np.uint8)


def _sample_strip(world: _World, rng: np.random.Generator, *, density: float, noise: float,
                  wall_density: float, outliers: int, returns: bool) -> dict[str, np.ndarray]:
    out = _Chunks()
    terrain = world.terrain
    w, h = world.size
    # ---- terrain
    if world.ground and density > 0:
        n = int(rng.poisson(density * w * h))
        xy = rng.random((n, 2)) * np.array([w, h])
        xy = xy[np.argsort(xy[:, 0], kind="stable")]  # x-sorted: objects test a slice (a view)
        xs = xy[:, 0]
        keep = np.ones(n, dtype=bool)
        for center, length, width, az in world.footprints:
            r = 0.5 * float(np.hypot(length, width))
            sl = x_window(xs, center[0] - r, center[0] + r)
            keep[sl][in_rectangle(xy[sl], center, length, width, az)] = False
        for obj, p_drop in [(t, 0.4) for t in world.trees] + [(s, 0.5) for s in world.shrubs]:
            r = obj.get("crown_radius", obj.get("radius"))
            c = obj["center"]
            sl = x_window(xs, c[0] - r, c[0] + r)
            under = np.hypot(xy[sl, 0] - c[0], xy[sl, 1] - c[1]) < r
            keep[sl][under & (rng.random(under.shape[0]) < p_drop)] = False
        xy = xy[keep]
        z = terrain.local_height(xy)
        xyz = np.column_stack([xy, z])
        eps = rng.normal(0.0, noise, len(xyz)) if noise > 0 else np.zeros(len(xyz))
        if world.ground_plane >= 0:
            xyz += eps[:, None] * world.planes[world.ground_plane]["normal"]
        else:
            xyz[:, 2] += eps
        out.add(xyz, CLASS_GROUND, True, -1, world.ground_plane)
        # ---- curb faces (vertical steps of the ground)
        for k, (px, py, ux, uy, half, step) in enumerate(terrain.roads):
            for side in (-1.0, 1.0):
                seg = _clip_line(np.array([px, py]), np.array([ux, uy]), side * half, (w, h))
                if seg is None:
                    continue
                a, b = seg
                length = float(np.linalg.norm(b - a))
                m = int(rng.poisson(wall_density * length * step))
                if m == 0:
                    continue
                t = rng.random(m)
                cxy = a + t[:, None] * (b - a)
                base = terrain.local_height(cxy, skip_road=k)
                cz = base + rng.random(m) * step
                nrm = np.array([-uy, ux]) * side
                if noise > 0:
                    cxy = cxy + rng.normal(0.0, noise, m)[:, None] * nrm
                # keep curb points outside object footprints
                ok = np.ones(m, dtype=bool)
                for center, length_, width_, az in world.footprints:
                    ok &= ~in_rectangle(cxy, center, length_, width_, az)
                out.add(np.column_stack([cxy[ok], cz[ok]]), CLASS_GROUND, True, -1, -1)
    # ---- planar faces (roofs, walls, cars)
    for f in world.faces:
        p = sample_polygon(rng, f.vertices, f.density)
        if len(p) == 0:
            continue
        if f.clip_below_terrain:
            p = p[p[:, 2] >= terrain.local_height(p[:, :2])]
        if noise > 0:
            p = p + rng.normal(0.0, noise, len(p))[:, None] * world.planes[f.plane]["normal"]
        out.add(p, f.classification, False, f.object_id, f.plane)
    # ---- trees
    for t in world.trees:
        r, rz = t["crown_radius"], t["crown_rz"]
        m = int(rng.poisson(density * np.pi * r * r * 1.2))
        d = rng.normal(size=(m, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        flip = rng.random(m) < 0.6
        d[flip, 2] = np.abs(d[flip, 2])
        s = 1.0 - 0.4 * rng.random(m) ** 2
        p = np.column_stack([t["center"][0] + r * s * d[:, 0], t["center"][1] + r * s * d[:, 1],
                             t["crown_z"] + rz * s * d[:, 2]])
        gz = terrain.local_height(p[:, :2])
        p = p[p[:, 2] > gz + 0.05]
        gz = terrain.local_height(p[:, :2])
        nret = 1
        if returns and len(p):
            nret = np.where(rng.random(len(p)) < 0.6, 2, 1).astype(np.uint8)
        out.add(p, _veg_class(p[:, 2] - gz), False, t["object_id"], -1, 1, nret)
        if returns and len(p):
            two = nret == 2
            gxy = p[two, :2] + rng.normal(0.0, 0.05, (int(two.sum()), 2))
            gp = np.column_stack([gxy, terrain.local_height(gxy) + rng.normal(0.0, noise, len(gxy))
                                  if noise > 0 else terrain.local_height(gxy)])
            out.add(gp, CLASS_GROUND, True, -1, world.ground_plane if world.ground_plane >= 0 else -1,
                    2, 2)
        # trunk
        tr, th = t["trunk_radius"], t["trunk_height"]
        m = int(rng.poisson(wall_density * 2 * np.pi * tr * th * 0.3))
        if m:
            ang = rng.random(m) * 2 * np.pi
            hz = rng.random(m) * (th + rz * 0.5)
            p = np.column_stack([t["center"][0] + tr * np.cos(ang), t["center"][1] + tr * np.sin(ang),
                                 t["ground_z"] + hz])
            out.add(p, _veg_class(hz), False, t["object_id"], -1)
    # ---- shrubs (low vegetation)
    for s in world.shrubs:
        r, sh = s["radius"], s["height"]
        m = int(rng.poisson(density * np.pi * r * r * 0.8))
        if m == 0:
            continue
        rr = r * np.sqrt(rng.random(m))
        ang = rng.random(m) * 2 * np.pi
        xy = s["center"] + np.column_stack([rr * np.cos(ang), rr * np.sin(ang)])
        top = sh * np.sqrt(np.clip(1.0 - (rr / r) ** 2, 0.0, 1.0))
        hag = top * rng.random(m) ** 0.3
        keep = hag > 0.08
        xy, hag = xy[keep], hag[keep]
        p = np.column_stack([xy, terrain.local_height(xy) + hag])
        out.add(p, _veg_class(hag), False, s["object_id"], -1)
    # ---- outliers
    if outliers > 0:
        xy = rng.random((outliers, 2)) * np.array([w, h])
        gz = terrain.local_height(xy)
        low = np.arange(outliers) % 2 == 0
        dz = np.where(low, -rng.uniform(1.0, 15.0, outliers), rng.uniform(20.0, 80.0, outliers))
        out.add(np.column_stack([xy, gz + dz]), CLASS_NOISE, False, -1, -1)
    return out.concat()


def _finish(world: _World, rng: np.random.Generator, *, density: float, noise: float,
            wall_density: float, outliers: int, returns: bool, strips: int,
            strip_offset: Sequence[float], origin: Sequence[float], min_plane_points: int,
            params: dict[str, Any]) -> Scene:
    parts = []
    for k in range(strips):
        d = _sample_strip(world, rng, density=density, noise=noise, wall_density=wall_density,
                          outliers=outliers, returns=returns)
        if k >= 1:
            d["xyz"] = d["xyz"] + np.asarray(strip_offset, dtype=np.float64) * k
        d["psid"] = np.full(len(d["xyz"]), k + 1, dtype=np.uint16)
        parts.append(d)
    data = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    order = rng.permutation(len(data["xyz"]))
    data = {key: v[order] for key, v in data.items()}

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


# --------------------------------------------------------------------- placement helpers


def _breaklines(terrain: TerrainModel) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """(point, unit normal, signed offset) of every break line, for keep-out tests."""
    out = []
    for px, py, ux, uy, half, _h in terrain.roads:
        for s in (-half, half):
            out.append((np.array([px, py]), np.array([-uy, ux]), s))
    for px, py, ux, uy, start, width, _h in terrain.embankments:
        # keep objects off the whole ramp
        out.append((np.array([px, py]), np.array([-uy, ux]), start + 0.5 * width, 0.5 * width))
    return out


def _place(rng: np.random.Generator, n: int, radii: Any, size: tuple[float, float],
           occupied: list[tuple[np.ndarray, float]], keepout: list, max_tries: int = 200) -> list:
    """Rejection-sample up to `n` non-overlapping discs; returns [(center, radius)]."""
    placed = []
    for _ in range(n):
        for _try in range(max_tries):
            r = float(radii())
            if 2 * r + 2 > min(size):
                break
            c = np.array([rng.uniform(r + 1, size[0] - r - 1), rng.uniform(r + 1, size[1] - r - 1)])
            ok = all(np.hypot(*(c - oc)) > r + orad + 1.0 for oc, orad in occupied)
            if ok:
                for item in keepout:
                    p, nrm, off = item[0], item[1], item[2]
                    extra = item[3] if len(item) > 3 else 0.0
                    if abs(float((c - p) @ nrm) - off) < r + extra + 0.5:
                        ok = False
                        break
            if ok:
                occupied.append((c, r))
                placed.append((c, r))
                break
    return placed


def _random_terrain(rng: np.random.Generator, size: tuple[float, float], *, slope_deg: float,
                    undulation: float, curbs: int, curb_height: float | None,
                    embankment: bool | float) -> TerrainModel:
    w, h = size
    az = rng.uniform(0, 2 * np.pi)
    g = np.tan(np.deg2rad(slope_deg))
    gx, gy = g * np.cos(az), g * np.sin(az)
    waves = np.zeros((0, 4))
    if undulation > 0:
        k = 3
        lam = rng.uniform(30.0, 120.0, k)
        ang = rng.uniform(0, 2 * np.pi, k)
        kk = 2 * np.pi / lam
        amp = undulation * rng.dirichlet(np.ones(k))
        waves = np.column_stack([amp, kk * np.cos(ang), kk * np.sin(ang), rng.uniform(0, 2 * np.pi, k)])
    roads = []
    for _ in range(int(curbs)):
        ang = rng.uniform(0, np.pi)
        p = np.array([rng.uniform(0.3, 0.7) * w, rng.uniform(0.3, 0.7) * h])
        step = float(curb_height) if curb_height is not None else float(rng.uniform(0.15, 0.3))
        roads.append([p[0], p[1], np.cos(ang), np.sin(ang), rng.uniform(3.0, 5.0), step])
    embs = []
    if embankment:
        ang = rng.uniform(0, np.pi)
        p = np.array([rng.uniform(0.2, 0.8) * w, rng.uniform(0.2, 0.8) * h])
        height = float(embankment) if not isinstance(embankment, bool) else float(rng.uniform(2, 4))
        embs.append([p[0], p[1], np.cos(ang), np.sin(ang), 0.0, rng.uniform(1.5, 3.0), height])
    return TerrainModel(z0=0.0, gx=float(gx), gy=float(gy), waves=waves,
                        roads=np.asarray(roads, float).reshape(-1, 6),
                        embankments=np.asarray(embs, float).reshape(-1, 7))


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


def _random_building(rng: np.random.Generator, roof: str, center: np.ndarray) -> BuildingSpec:
    if roof == "flat":
        return BuildingSpec("flat", (float(center[0]), float(center[1])),
                            float(rng.uniform(10, 20)), float(rng.uniform(7, 14)),
                            float(rng.uniform(0, 180)), float(rng.uniform(4, 12)), 0.0)
    return BuildingSpec("gable", (float(center[0]), float(center[1])),
                        float(rng.uniform(10, 18)), float(rng.uniform(7, 11)),
                        float(rng.uniform(0, 180)), float(rng.uniform(3, 7)),
                        float(rng.uniform(25, 45)))


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

    Returns
    -------
    Scene
    """
    size = _check_size(size)
    wd = _check_common(density, noise, wall_density, strips, min_plane_points)
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
    drafts = [_random_building(rng, roofs[i % len(roofs)], np.zeros(2)) for i in range(n_buildings)]
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
    for c, _r in _place(rng, n_trees, lambda: 2.5, size, occupied, []):
        _add_tree(world, rng, c)
    for c, _r in _place(rng, n_shrubs, lambda: 1.5, size, occupied, []):
        _add_shrub(world, rng, c)
    params = {
        "maker": "make_scene", "seed": seed, "size": list(size), "density": density,
        "noise": noise, "wall_density": wd, "roofs": list(roofs), "slope_deg": slope_deg,
        "undulation": undulation, "curbs": curbs, "curb_height": curb_height,
        "embankment": embankment, "outliers": outliers, "returns": returns, "strips": strips,
        "strip_offset": [float(v) for v in strip_offset], "origin": [float(v) for v in origin],
        "foot_edges": foot_edges, "min_plane_points": min_plane_points,
        "counts": {"buildings": len(buildings), "cars": len(cars), "trees": len(world.trees),
                   "shrubs": len(world.shrubs)},
        "buildings": [asdict(b) for b in buildings],
        "cars": [asdict(c) for c in cars],
    }
    return _finish(world, rng, density=density, noise=noise, wall_density=wd, outliers=outliers,
                   returns=returns, strips=strips, strip_offset=strip_offset, origin=origin,
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

    Returns
    -------
    Scene
        Edge kinds ``ridge``, ``eave``, ``verge``, ``wall``, ``foot``; corner kinds
        ``ridge``, ``eave``, ``foot``.
    """
    wd = _check_common(density, noise, wall_density, strips, min_plane_points)
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
            spec = _random_building(rng, roof, np.zeros(2))
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
        "spacing": spacing, "slope_deg": slope_deg, "ground": ground, "foot_edges": foot_edges,
        "strips": strips, "strip_offset": [float(v) for v in strip_offset],
        "origin": [float(v) for v in origin], "min_plane_points": min_plane_points,
        "counts": {"buildings": len(specs)},
        "buildings": [asdict(b) for b in specs],
    }
    return _finish(world, rng, density=density, noise=noise, wall_density=wd, outliers=0,
                   returns=False, strips=strips, strip_offset=strip_offset, origin=origin,
                   min_plane_points=min_plane_points, params=params)


def plane_area(plane: TruePlane) -> float:
    """Area (m^2) of a plane's sampled face (NaN for the ground)."""
    return float("nan") if plane.polygon is None else polygon_area(plane.polygon)
