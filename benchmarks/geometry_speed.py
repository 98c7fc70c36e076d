"""Speed and memory of plane segmentation + edge extraction on ~1 M synthetic building points.

Run:  /work/venv/bin/python benchmarks/geometry_speed.py [--points 1000000] [--repeat 2]
      [--strips]    also: per IGN tile (class 6), edges per strip 706/707 and the
                    distance between the same edges found in both strips
      [--open3d PYTHON]  time open3d's segment_plane (one RANSAC plane) with that
                    interpreter (open3d need not be installed in lidarqa's venv)

Prints tables; timing goals live here, never in the unit tests. Numba compilation
is excluded (a warm-up run on a small scene comes first). CPU time is printed
next to wall time because the machine may be shared.
"""

from __future__ import annotations

import argparse
import glob
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _scene(n_points: int, seed: int = 0):
    from lidarqa.testing import make_building_scene

    per_building = 39_000  # about 40 m x 40 m of ground + one building at 20 pts/m²
    nb = max(1, round(n_points / per_building))
    roofs = ("flat", "gable") * (nb // 2) + ("gable",) * (nb % 2)
    return make_building_scene(seed=seed, roofs=roofs, density=20.0, noise=0.02)


def run_speed(n_points: int, repeat: int) -> None:
    from lidarqa.geometry.corners import corners_from_segmentation
    from lidarqa.geometry.edges import edges_from_segmentation
    from lidarqa.geometry.segmentation import segment_planes, surface_growing
    from lidarqa.testing import score_edges

    warm = _scene(50_000, seed=1)  # compile the numba kernels (cached on disk afterwards)
    seg = segment_planes(warm.points)
    edges_from_segmentation(warm.points, seg)
    corners_from_segmentation(seg, warm.points)

    sc = _scene(n_points)
    pts = sc.points
    base = _rss_mb()
    print(f"scene: {len(pts):,} points, {len(sc.planes)} true planes, {len(sc.edges)} true edges; "
          f"peak RSS before the run {base:.0f} MB")
    print(f"{'step':34s} {'wall s':>8s} {'cpu s':>8s}")
    rows = []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        seg = segment_planes(pts)
        t1, c1 = time.perf_counter(), time.process_time()
        edges, _ = edges_from_segmentation(pts, seg)
        t2, c2 = time.perf_counter(), time.process_time()
        corners, _ = corners_from_segmentation(seg, pts)
        t3, c3 = time.perf_counter(), time.process_time()
        rows.append((t1 - t0, c1 - c0, t2 - t1, c2 - c1, t3 - t2, c3 - c2))
    best = min(rows, key=lambda r: r[0] + r[2])
    print(f"{'segment_planes':34s} {best[0]:8.2f} {best[1]:8.2f}")
    print(f"{'edges_from_segmentation':34s} {best[2]:8.2f} {best[3]:8.2f}")
    print(f"{'segmentation + edges':34s} {best[0] + best[2]:8.2f} {best[1] + best[3]:8.2f}")
    print(f"{'corners_from_segmentation':34s} {best[4]:8.2f} {best[5]:8.2f}")
    for method in ("pca", "ransac", "hough"):
        t0, c0 = time.perf_counter(), time.process_time()
        surface_growing(pts, seed_method=method)
        print(f"{'surface_growing seed=' + method:34s} {time.perf_counter() - t0:8.2f} "
              f"{time.process_time() - c0:8.2f}")
    score = score_edges(edges, sc.edges)
    print(f"peak RSS {_rss_mb():.0f} MB (process; {_rss_mb() - base:.0f} MB above the scene)")
    print(f"{seg.n_segments} planes, {len(edges)} edges, {len(corners)} corners; "
          f"true edges >= 2 m found within 3 cm / 70 %: {score.n_matched}/{score.n_true} "
          f"({score.recall:.1%}), worst RMS {np.nanmax(score.rms) * 1000:.1f} mm")


def run_open3d(python: str, n_points: int) -> None:
    code = f"""
import time, numpy as np, open3d as o3d, sys
sys.path.insert(0, {str(Path(__file__).resolve().parents[1] / 'src')!r})
pts = np.load(sys.argv[1])
pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
o3d.utility.random.seed(0)
t = time.perf_counter()
model, inl = pc.segment_plane(distance_threshold=0.05, ransac_n=3, num_iterations=1000)
print(f"open3d {{o3d.__version__}} segment_plane (1 plane, 1000 iterations) "
      f"on {{len(pts):,}} points: "
      f"{{time.perf_counter() - t:.2f}} s, {{len(inl):,}} inliers")
"""
    sc = _scene(n_points)
    tmp = Path("/tmp/_geometry_speed_points.npy")
    np.save(tmp, sc.points)
    subprocess.run([python, "-c", code, str(tmp)], check=False)
    tmp.unlink()


def _match_distance(a, b, max_angle: float = 5.0, max_dist: float = 1.0) -> np.ndarray:
    out = []
    ub = (b.end - b.start) / b.lengths[:, None]
    for i in range(len(a)):
        ua = (a.end[i] - a.start[i]) / a.lengths[i]
        mid = (a.start[i] + a.end[i]) / 2
        ok = np.degrees(np.arccos(np.clip(np.abs(ub @ ua), 0, 1))) <= max_angle
        t0 = np.einsum("ij,ij->i", a.start[i] - b.start, ub)
        t1 = np.einsum("ij,ij->i", a.end[i] - b.start, ub)
        ok &= (np.minimum(np.maximum(t0, t1), b.lengths) - np.maximum(np.minimum(t0, t1), 0)) > 0
        w = mid - b.start
        d = np.linalg.norm(w - np.einsum("ij,ij->i", w, ub)[:, None] * ub, axis=1)
        d = np.where(ok, d, np.inf)
        if d.min() <= max_dist:
            out.append(d.min())
    return np.array(out)


def _ridges(e, seg):
    """The ridge edges of `e`: horizontal, between two sloped roofs, convex."""
    if not len(e):
        return e
    d = (e.end - e.start) / e.lengths[:, None]
    na, nb = seg.normal[e.attributes["plane_a"]], seg.normal[e.attributes["plane_b"]]
    tilt_a = np.degrees(np.arccos(np.clip(na[:, 2], -1, 1)))
    tilt_b = np.degrees(np.arccos(np.clip(nb[:, 2], -1, 1)))
    mid = (e.start + e.end) / 2
    # convex: each plane's centroid lies below the edge, on opposite sides horizontally
    ca = seg.centroid[e.attributes["plane_a"]] - mid
    cb = seg.centroid[e.attributes["plane_b"]] - mid
    convex = (ca[:, 2] < 0) & (cb[:, 2] < 0) & (np.einsum("ij,ij->i", ca[:, :2], cb[:, :2]) < 0)
    keep = ((np.abs(d[:, 2]) < 0.1) & (tilt_a > 10) & (tilt_a < 70) & (tilt_b > 10) & (tilt_b < 70)
            & convex)
    return e.subset(keep)


def run_strips() -> None:
    import lidarqa
    from lidarqa.geometry.edges import edges_from_segmentation
    from lidarqa.geometry.segmentation import segment_planes

    files = sorted(glob.glob(str(Path(__file__).resolve().parents[2] / "shared" / "lidar-data"
                                 / "ign-lidarhd" / "test_data_*.laz")))
    print(f"{'tile':14s} {'pts706':>7s} {'pts707':>7s} {'edges706':>8s} {'edges707':>8s} "
          f"{'horiz706':>8s} {'horiz707':>8s} {'matched':>7s} {'median_d_m':>10s} "
          f"{'rdg706':>7s} {'rdg707':>7s} {'rdg_mat':>7s} {'rdg_med_m':>10s}")
    for f in files:
        cloud = lidarqa.read(f)
        res = {}
        for s in (706, 707):
            sub = cloud.select(classes=6, source_id=s)
            if len(sub) < 50:
                res[s] = (len(sub), None, None)
                continue
            seg = segment_planes(sub.xyz)
            e, _ = edges_from_segmentation(sub.xyz, seg)
            res[s] = (len(sub), e, _ridges(e, seg))
        e6, e7 = res[706][1], res[707][1]

        def n_h(e):
            if e is None or not len(e):
                return 0
            return int((np.abs((e.end - e.start)[:, 2]) / e.lengths < 0.1).sum())

        d = _match_distance(e6, e7) if e6 is not None and e7 is not None and len(e6) and len(e7) \
            else np.zeros(0)
        r6, r7 = res[706][2], res[707][2]
        dr = _match_distance(r6, r7) if r6 is not None and r7 is not None and len(r6) and len(r7) \
            else np.zeros(0)
        tile = Path(f).stem.replace("test_data_", "").replace("_LA93_IGN69", "")
        print(f"{tile:14s} {res[706][0]:7d} {res[707][0]:7d} "
              f"{len(e6) if e6 is not None else 0:8d} {len(e7) if e7 is not None else 0:8d} "
              f"{n_h(e6):8d} {n_h(e7):8d} {len(d):7d} "
              f"{np.median(d) if len(d) else float('nan'):10.3f} "
              f"{len(r6) if r6 is not None else 0:7d} {len(r7) if r7 is not None else 0:7d} "
              f"{len(dr):7d} {np.median(dr) if len(dr) else float('nan'):10.3f}")
    print("matched: edges of 706 with an edge of 707 within 5 degrees, overlapping, midpoint "
          "within 1 m of its line; median_d_m: median perpendicular distance (m).\n"
          "ridges: horizontal edges (|dz|/length < 0.1) between two roof planes tilted 10-70 "
          "degrees whose normals point away from each other (convex).")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--strips", action="store_true")
    ap.add_argument("--open3d", metavar="PYTHON", default=None)
    ap.add_argument("--no-speed", action="store_true")
    a = ap.parse_args(argv)
    if not a.no_speed:
        run_speed(a.points, a.repeat)
    if a.open3d:
        run_open3d(a.open3d, a.points)
    if a.strips:
        run_strips()


if __name__ == "__main__":
    sys.exit(main())
