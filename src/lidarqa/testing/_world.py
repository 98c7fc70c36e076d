"""Private: build the noise-free world of a scene and sample it like a scanner.

Everything works in the scene's local frame (extent from 0, 0); the public
makers in :mod:`.scenes` move the result to the requested origin.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validate import check_choice, check_positive
from ..errors import OptionError
from ._shapes import (
    CLASS_BUILDING,
    CLASS_GROUND,
    CLASS_HIGH_VEG,
    CLASS_LOW_VEG,
    CLASS_MEDIUM_VEG,
    CLASS_NOISE,
    CLASS_OTHER,
    ColumnSampler,
    Face,
    TerrainModel,
    _clip_line,
    canonical_plane,
    in_rectangle,
    rect_corners,
    sample_polygon,
    sample_polygon_jittered,
)

__all__ = ["BuildingSpec", "ROOF_TYPES"]

ROOF_TYPES = ("flat", "gable")


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
    overhang : float
        Horizontal roof overhang beyond the walls (m). The eave edges stay the
        wall-roof intersections; the roof outline becomes a step edge (not in
        the truth) and the ground under the overhang is hidden.
    """

    roof: str = "flat"
    center: tuple[float, float] = (20.0, 20.0)
    length: float = 15.0
    width: float = 10.0
    azimuth_deg: float = 0.0
    height: float = 6.0
    pitch_deg: float = 35.0
    overhang: float = 0.0

    def __post_init__(self) -> None:
        check_positive(self.overhang, "overhang", allow_zero=True)
        check_choice(self.roof, ROOF_TYPES, "roof")
        check_positive(self.length, "length")
        check_positive(self.width, "width")
        check_positive(self.height, "height")
        if self.roof == "gable" and not 0.0 < float(self.pitch_deg) < 90.0:
            raise OptionError(f"pitch_deg must be in (0, 90) degrees, got {self.pitch_deg!r}")

    @property
    def radius(self) -> float:
        o2 = 2 * self.overhang
        return 0.5 * float(np.hypot(self.length + o2, self.width + o2))


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
    o = 0.0 if is_car else float(spec.overhang)
    # the roof hides the ground under the overhang too
    world.footprints.append((np.asarray(spec.center, float), spec.length + 2 * o,
                             spec.width + 2 * o, spec.azimuth_deg))
    az = np.deg2rad(spec.azimuth_deg)
    ex = np.array([np.cos(az), np.sin(az)])
    ey = np.array([-np.sin(az), np.cos(az)])
    ctr = np.asarray(spec.center, dtype=np.float64)

    def p3(xy: np.ndarray, z: float) -> np.ndarray:
        return np.array([xy[0], xy[1], z])

    def loc(lx: float, ly: float, z: float) -> np.ndarray:
        return p3(ctr + lx * ex + ly * ey, z)

    hl, hw = 0.5 * spec.length, 0.5 * spec.width
    roof_ids: list[int] = []
    if spec.roof == "flat" or is_car:
        poly = np.array([loc(sx * (hl + o), sy * (hw + o), top)
                         for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
        rid = world.add_plane(np.array([0.0, 0.0, 1.0]), poly[0], roof_kind, oid, poly)
        world.faces.append(Face(poly, rid, cls, oid, density, airborne=True))
        roof_ids = [rid]
        wall_tops = {i: [p3(c2[i], top), p3(c2[(i + 1) % 4], top)] for i in range(4)}
        ridge = None
    else:
        slope = np.tan(np.deg2rad(spec.pitch_deg))
        zr = top + hw * slope
        zo = top - o * slope
        ridge = (loc(-hl, 0.0, zr), loc(hl, 0.0, zr))  # where the ridge meets the gable walls
        ridge_ends = (loc(-hl - o, 0.0, zr), loc(hl + o, 0.0, zr))
        face_a = np.array([loc(-hl - o, -hw - o, zo), loc(hl + o, -hw - o, zo), ridge_ends[1],
                           ridge_ends[0]])
        face_b = np.array([loc(hl + o, hw + o, zo), loc(-hl - o, hw + o, zo), ridge_ends[0],
                           ridge_ends[1]])
        for poly in (face_a, face_b):
            n = _plane_normal(poly)
            rid = world.add_plane(n, poly[0], roof_kind, oid, poly)
            # airborne density per horizontal m^2 -> per surface m^2
            nz = abs(world.planes[rid]["normal"][2])
            world.faces.append(Face(poly, rid, cls, oid, density * nz, airborne=True))
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
        world.edges.append((ridge_ends[0], ridge_ends[1], ra, rb, "ridge", oid))
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


def _add_tree(world: _World, rng: np.random.Generator, center: np.ndarray,
              crown_radius: float) -> None:
    oid = world.new_object()
    gz = float(world.terrain.local_height(center[None, :])[0])
    trunk_h = float(rng.uniform(1.5, 4.0))
    crown_rz = float(rng.uniform(1.5, 4.0))
    world.trees.append({
        "object_id": oid, "center": center, "ground_z": gz, "trunk_height": trunk_h,
        "trunk_radius": float(rng.uniform(0.12, 0.3)), "crown_radius": float(crown_radius),
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
            empty: dict[str, np.ndarray] = {"xyz": np.zeros((0, 3)), "cls": np.zeros(0, np.uint8),
                     "ground": np.zeros(0, bool), "oid": np.zeros(0, np.int64),
                     "pid": np.zeros(0, np.int64), "ret": np.zeros(0, np.uint8),
                     "nret": np.zeros(0, np.uint8)}
            return empty
        return {k: np.concatenate([p[k] for p in self.parts]) for k in keys}


def _veg_class(hag: np.ndarray) -> np.ndarray:
    return np.where(hag > 2.0, CLASS_HIGH_VEG,
                    np.where(hag > 0.5, CLASS_MEDIUM_VEG, CLASS_LOW_VEG)).astype(np.uint8)


def _sample_strip(world: _World, rng: np.random.Generator, *, density: float, noise: float,
                  wall_density: float, outliers: int, returns: bool,
                  pattern: str = "random") -> dict[str, np.ndarray]:
    out = _Chunks()
    terrain = world.terrain
    w, h = world.size
    # ---- terrain
    if world.ground and density > 0:
        jittered = pattern == "jittered"
        n = round(density * w * h) if jittered else int(rng.poisson(density * w * h))
        # grouped by x column: objects test a slice
        cols = ColumnSampler(rng, n, (w, h), jittered=jittered)
        xy = cols.xy
        n = len(xy)
        keep = np.ones(n, dtype=bool)
        for center, length, width, az in world.footprints:
            r = 0.5 * float(np.hypot(length, width))
            sl = cols.window(center[0] - r, center[0] + r)
            keep[sl][in_rectangle(xy[sl], center, length, width, az)] = False
        for obj, p_drop in [(t, 0.4) for t in world.trees] + [(s, 0.5) for s in world.shrubs]:
            rad = obj.get("crown_radius", obj.get("radius"))
            c = obj["center"]
            sl = cols.window(c[0] - rad, c[0] + rad)
            under = np.hypot(xy[sl, 0] - c[0], xy[sl, 1] - c[1]) < rad
            keep[sl][under & (rng.random(under.shape[0]) < p_drop)] = False
        xy = np.compress(keep, xy, axis=0)
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
                frac = rng.random(m)
                cxy = a + frac[:, None] * (b - a)
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
        if pattern == "jittered":
            p = sample_polygon_jittered(rng, f.vertices, f.density,
                                        world.planes[f.plane]["normal"], f.airborne)
        else:
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
        shrink = 1.0 - 0.4 * rng.random(m) ** 2
        p = np.column_stack([t["center"][0] + r * shrink * d[:, 0],
                             t["center"][1] + r * shrink * d[:, 1],
                             t["crown_z"] + rz * shrink * d[:, 2]])
        gz = terrain.local_height(p[:, :2])
        p = p[p[:, 2] > gz + 0.05]
        gz = terrain.local_height(p[:, :2])
        nret: Any = 1
        if returns and len(p):
            nret = np.where(rng.random(len(p)) < 0.6, 2, 1).astype(np.uint8)
        out.add(p, _veg_class(p[:, 2] - gz), False, t["object_id"], -1, 1, nret)
        if returns and len(p):
            two = nret == 2
            gxy = p[two, :2] + rng.normal(0.0, 0.05, (int(two.sum()), 2))
            gz = terrain.local_height(gxy)
            if noise > 0:
                gz = gz + rng.normal(0.0, noise, len(gxy))
            out.add(np.column_stack([gxy, gz]), CLASS_GROUND, True, -1, world.ground_plane, 2, 2)
        # trunk
        tr, th = t["trunk_radius"], t["trunk_height"]
        m = int(rng.poisson(wall_density * 2 * np.pi * tr * th * 0.3))
        if m:
            ang = rng.random(m) * 2 * np.pi
            hz = rng.random(m) * (th + rz * 0.5)
            p = np.column_stack([t["center"][0] + tr * np.cos(ang),
                                 t["center"][1] + tr * np.sin(ang), t["ground_z"] + hz])
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


# --------------------------------------------------------------------- placement helpers


def _breaklines(terrain: TerrainModel) -> list[tuple[Any, ...]]:
    """(point, unit normal, signed offset[, half width]) of every break line, for keep-out tests.

    An embankment adds its ramp's half width (objects stay off the whole ramp).
    """
    out: list[tuple[Any, ...]] = []
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
    oc = np.array([o[0] for o in occupied], dtype=np.float64).reshape(-1, 2)
    orad = np.array([o[1] for o in occupied], dtype=np.float64)
    for _ in range(n):
        for _try in range(max_tries):
            r = float(radii())
            if 2 * r + 2 > min(size):
                break
            c = np.array([rng.uniform(r + 1, size[0] - r - 1), rng.uniform(r + 1, size[1] - r - 1)])
            ok = bool(np.all(np.hypot(oc[:, 0] - c[0], oc[:, 1] - c[1]) > r + orad + 1.0))
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
                oc = np.vstack([oc, c])
                orad = np.append(orad, r)
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
        phase = rng.uniform(0, 2 * np.pi, k)
        waves = np.column_stack([amp, kk * np.cos(ang), kk * np.sin(ang), phase])
    roads = []
    for _ in range(int(curbs)):
        road_ang = rng.uniform(0, np.pi)
        p = np.array([rng.uniform(0.3, 0.7) * w, rng.uniform(0.3, 0.7) * h])
        step = float(curb_height) if curb_height is not None else float(rng.uniform(0.15, 0.3))
        roads.append([p[0], p[1], np.cos(road_ang), np.sin(road_ang), rng.uniform(3.0, 5.0), step])
    embs = []
    if embankment:
        emb_ang = rng.uniform(0, np.pi)
        p = np.array([rng.uniform(0.2, 0.8) * w, rng.uniform(0.2, 0.8) * h])
        height = float(embankment) if not isinstance(embankment, bool) else float(rng.uniform(2, 4))
        embs.append(
            [p[0], p[1], np.cos(emb_ang), np.sin(emb_ang), 0.0, rng.uniform(1.5, 3.0), height]
        )
    return TerrainModel(z0=0.0, gx=float(gx), gy=float(gy), waves=waves,
                        roads=np.asarray(roads, float).reshape(-1, 6),
                        embankments=np.asarray(embs, float).reshape(-1, 7))


def _random_building(rng: np.random.Generator, roof: str, center: np.ndarray) -> BuildingSpec:
    if roof == "flat":
        return BuildingSpec("flat", (float(center[0]), float(center[1])),
                            float(rng.uniform(10, 20)), float(rng.uniform(7, 14)),
                            float(rng.uniform(0, 180)), float(rng.uniform(4, 12)), 0.0)
    return BuildingSpec("gable", (float(center[0]), float(center[1])),
                        float(rng.uniform(10, 18)), float(rng.uniform(7, 11)),
                        float(rng.uniform(0, 180)), float(rng.uniform(3, 7)),
                        float(rng.uniform(25, 45)))
