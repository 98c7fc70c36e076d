"""``lidarqa qc PATHS -o OUTDIR --spec usgs-ql2``: delivery acceptance, one verdict per tile."""

from __future__ import annotations

from typing import Any

import click

from ._common import Steps, common_options, crs_option, echo, finish, prepare_outputs, settings


@click.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path())
@click.option("-o", "--out", "out", required=True, type=click.Path(file_okay=False),
              help="Output folder: qc.json, qc.gpkg (tiles, voids), density.tif, qc.html.")
@click.option("--spec", default="usgs-ql2", show_default=True,
              help="usgs-ql0, usgs-ql1, usgs-ql2, usgs-ql3, or a .toml file of limits.")
@click.option("--checkpoints", type=click.Path(dir_okay=False), default=None,
              help="Surveyed check points (id,x,y,z): NVA at the ground TIN "
                   "(as `checkpoints --vertical`).")
@click.option("--land-cover", default=None,
              help="Column of --checkpoints with the land cover: vegetated points give the "
                   "VVA (reported, not judged), the others the NVA.")
@click.option("--checkpoint-rmse-v", type=float, default=0.0, show_default=True,
              help="Vertical RMSE of the check-point survey (m), folded in (ASPRS Ed. 2).")
@click.option("--reference", type=click.Path(), default=None,
              help="Reference classification (a point cloud or catalog): confusion matrix, κ.")
@click.option("--reference-tolerance", type=float, default=0.0, show_default=True,
              help="Largest distance (m) to the matched reference point (0: the same points).")
@click.option("--exclude", type=click.Path(dir_okay=False), default=None,
              help="Polygons (GeoPackage/GeoJSON) left out of the voids, e.g. water bodies.")
@click.option("--workers", type=int, default=None,
              help="Local worker processes (default 1 = serial, no Dask).")
@click.option("--scheduler", default=None,
              help="Dask scheduler address (tcp://host:port) or 'serial'.")
@click.option("--relative-accuracy", is_flag=True, default=False,
              help="Also judge relative accuracy: the swath analysis (strips by point source "
                   "id) against the spec's smooth-surface and swath-overlap limits.")
@click.option("--ground-consistency", is_flag=True, default=False,
              help="Also map where lidarqa's ground filter disagrees with the delivery's "
                   "class 2 (information, not judged; slow: filters every point).")
@crs_option
@common_options
def qc(paths: tuple[str, ...], out: str, spec: str, checkpoints: str | None,
       land_cover: str | None, checkpoint_rmse_v: float, reference: str | None,
       reference_tolerance: float, exclude: str | None, workers: int | None,
       scheduler: str | None, relative_accuracy: bool, ground_consistency: bool,
       crs: str | None) -> None:
    """Check a delivery (PATHS: files, folders, globs, a .vpc) against an acceptance spec.

    Per tile: LAS version and point format, CRS as WKT, GPS time type, return
    numbers, class codes, header against data, duplicates, source ids, flags, scan
    angle; first-return density (ANPD, single swath, overlap excluded), spatial
    distribution (2 x ANPS cells) and voids ((4 x ANPS)², water excepted). Each
    check is pass, warn or fail with its value, limit and message. A tile that
    cannot be read, or in another CRS than the block, fails; the run goes on.
    Exit status 4 when any tile (or the NVA) fails.
    """
    from ..qc import get_spec, run_qc
    from ..qc.outputs import check_outputs
    from ..tiling import Engine

    s = settings()
    sp = get_spec(spec)  # an unknown spec name fails before any work
    prepare_outputs(inputs=tuple(paths))
    check_outputs(out, overwrite=s.overwrite)
    steps = Steps()
    if scheduler is None and (workers is None or workers == 1):
        engine = Engine("serial")
    else:
        engine = Engine(scheduler, workers=workers)
    with steps(f"Checking {len(paths)} input(s) against {sp.name}"), engine:
        result = run_qc(list(paths), sp, out=out, overwrite=s.overwrite,
                        checkpoints=checkpoints, land_cover=land_cover,
                        checkpoint_rmse_v=checkpoint_rmse_v, reference=reference,
                        reference_tolerance=reference_tolerance, exclude=exclude,
                        engine=engine, progress=not s.quiet, crs=crs,
                        relative_accuracy=relative_accuracy,
                        ground_consistency=ground_consistency)
    summ = result.summary()
    echo(f"{sp.title}: {summ['n_tiles']} tile(s), {summ['n_pass']} pass, {summ['n_warn']} warn, "
         f"{summ['n_fail']} fail")
    for k, n in summ["failed_by_check"].items():
        echo(f"  {k:<22} {n} tile(s) fail")
    for k, b in result.block.items():
        echo(f"  {k:<22} {b.get('status', '').upper():<5} {b.get('message', '')}")
    echo(f"Report: {result.outputs.get('html', result.outputs.get('json'))}")
    doc: dict[str, Any] = result.to_dict()
    finish("qc", inputs={"paths": list(paths), "checkpoints": checkpoints,
                         "reference": reference, "exclude": exclude},
           parameters={"spec": sp.name, "land_cover": land_cover,
                       "checkpoint_rmse_v": checkpoint_rmse_v,
                       "reference_tolerance": reference_tolerance, "out": out, "crs": crs,
                       "relative_accuracy": relative_accuracy,
                       "ground_consistency": ground_consistency},
           results=doc)
    if result.status == "fail":
        from ..errors import TargetNotMetError

        failed = result.failed_tiles
        what = [f"{len(failed)} of {summ['n_tiles']} tile(s) fail"] if failed else []
        what += [f"{k} fails" for k, b in result.block.items() if b.get("status") == "fail"]
        raise TargetNotMetError(f"{'; '.join(what)} the {sp.name} acceptance "
                                f"(details in {result.outputs.get('html', out)})")
