"""``lidarqa lines`` and ``lidarqa repeatability``: 3D line-segment matching (modified LHD)."""

from __future__ import annotations

import csv
from collections.abc import Callable
from itertools import combinations
from pathlib import Path
from typing import Any

import click

from ..units import format_decimal
from ._catalog import (
    catalog_options,
    catalog_options_given,
    failed_exit,
    finish_run,
    open_catalog_source,
    run_job,
    wants_catalog,
)
from ._common import (
    INT_LIST,
    Steps,
    classes_option,
    common_options,
    crs_option,
    echo,
    echo_tables,
    finish,
    fmt_number,
    input_crs,
    prepare_outputs,
    settings,
)


def _matching_options(func: Callable[..., Any]) -> Callable[..., Any]:
    opts: list[Callable[..., Any]] = [
        click.option(
            "--weight",
            default=10.0,
            show_default=True,
            type=float,
            help="Weight W of the squared angle distance (dimensionless).",
        ),
        click.option(
            "--sensitivity",
            default=0.1,
            show_default=True,
            type=float,
            help="A-priori sensitivity of the automatic threshold (m).",
        ),
        click.option(
            "--threshold",
            type=float,
            default=None,
            metavar="D",
            help="Fixed correspondence threshold (m) instead of the automatic one.",
        ),
        click.option(
            "--rotate",
            type=click.Choice(["shorter", "test"]),
            default="shorter",
            show_default=True,
            help="Segment rotated in each pair (shorter: symmetric).",
        ),
        click.option(
            "--denominator",
            type=click.Choice(["matched", "all"]),
            default="matched",
            show_default=True,
            help="OLHD denominator: lengths of matched pairs, or of all segments.",
        ),
        classes_option(help="Point-cloud input: classes whose edges are extracted, e.g. 6."),
        crs_option,
    ]
    for opt in reversed(opts):
        func = opt(func)
    return func


@click.command()
@click.argument("test", type=click.Path())
@click.argument("model", type=click.Path())
@_matching_options
@click.option(
    "--ground-truth",
    type=click.Path(dir_okay=False),
    default=None,
    metavar="PAIRS.csv",
    help="True pairs (columns test_id,model_id): adds TP/FP/FN/TN and detection rates.",
)
@click.option(
    "--matrix",
    type=click.Path(dir_okay=False),
    default=None,
    metavar="SIM.csv",
    help="Write the p×q similarity matrix (rows test ids, columns model ids; pruned pairs empty).",
)
@click.option(
    "--pairs",
    "pairs_out",
    type=click.Path(dir_okay=False),
    default=None,
    metavar="PAIRS_OUT.csv",
    help="Write the matched pairs (test_id,model_id, distances, direction flags).",
)
@click.option(
    "--test-source-id",
    type=INT_LIST,
    default=None,
    help="Point-cloud input: point_source_id(s) (flight strip) of the test points.",
)
@click.option(
    "--model-source-id",
    type=INT_LIST,
    default=None,
    help="Point-cloud input: point_source_id(s) (flight strip) of the model points.",
)
@catalog_options
@common_options
def lines(
    test: str,
    model: str,
    weight: float,
    sensitivity: float,
    threshold: float | None,
    rotate: str,
    denominator: str,
    classes: list[int] | None,
    ground_truth: str | None,
    matrix: str | None,
    pairs_out: str | None,
    test_source_id: list[int] | None,
    model_source_id: list[int] | None,
    crs: str | None,
    **cat_opts: Any,
) -> None:
    """Match TEST line segments to MODEL segments; OLHD both ways and LHD (Poreba & Goulette 2013).

    TEST and MODEL are segment files (CSV id,x1,y1,z1,x2,y2,z2, GeoPackage, GeoJSON) or
    point clouds, whose edges are extracted (select with --classes and --*-source-id, so
    two strips of one file can be compared). A cloud may be a catalog (several files, a
    folder, a glob, a .vpc): its edges are then found chunk by chunk, each edge once.
    """
    from ..accuracy.lines import match_segments
    from ..accuracy.lines_io import read_pairs
    from ..tiling.source import Selection

    given = input_crs(crs)
    inputs = tuple(x for x in (test, model, ground_truth) if x)
    prepare_outputs(matrix, pairs_out, inputs=inputs)
    steps = Steps()
    test_label = Selection.of(classes, test_source_id).label(test)
    model_label = Selection.of(classes, model_source_id).label(model)
    t = _side_segments("test", test, test_label, classes, test_source_id, given, steps, cat_opts)
    m = _side_segments("model", model, model_label, classes, model_source_id, given, steps,
                       cat_opts)
    gt = None
    if ground_truth:
        with steps("Reading ground truth"):
            gt = read_pairs(ground_truth)
    with steps(f"Matching {len(t)} × {len(m)} segments") as progress:
        r = match_segments(
            t,
            m,
            weight=weight,
            sensitivity=sensitivity,
            threshold=threshold,
            rotate=rotate,
            denominator=denominator,
            ground_truth=gt,
            progress=progress,
        )
    from .._atomic import atomic_path

    overwrite = settings().overwrite
    if matrix:
        with steps("Writing similarity matrix"), atomic_path(matrix, overwrite=overwrite) as tmp:
            _write_matrix(r, tmp)
    if pairs_out:
        with steps("Writing pairs"), atomic_path(pairs_out, overwrite=overwrite) as tmp:
            _write_pairs(r, tmp)
    from ..report.analyses.lines import lines_table

    d = r.to_dict()
    echo(f"test   {test_label}: p = {r.p} segments")
    echo(f"model  {model_label}: q = {r.q} segments")
    echo_tables(lines_table(r))
    finish(
        "lines",
        inputs={"test": test, "model": model, "ground_truth": ground_truth},
        parameters={
            "weight": weight,
            "sensitivity": sensitivity,
            "threshold": threshold,
            "rotate": rotate,
            "denominator": denominator,
            "classes": classes,
            "test_source_id": test_source_id,
            "model_source_id": model_source_id,
            "crs": crs,
        },
        results=d,
    )


def _side_segments(side: str, path: str, label: str, classes: Any, source_id: Any, given: Any,
                   steps: Steps, cat_opts: dict[str, Any]) -> Any:
    """One side's segments: a segment file, a cloud's edges, or a catalog's edges.

    A catalog is read chunk by chunk (each edge once) through a source with this side's
    selection.
    """
    import numpy as np

    from ..accuracy.lines_io import load_segments
    from ..io.vector import heights_in_metres
    from ..tiling.source import is_catalog_input

    if is_catalog_input(path) or Path(path).suffix.lower() in (".las", ".laz"):
        from ..errors import NothingToMeasureError
        from ..tiling.jobs_api import catalog_features

        try:
            import lidarqa.geometry.edges  # noqa: F401
        except ImportError:
            from ..accuracy.lines_io import extract_segments

            extract_segments(np.empty((0, 3)))  # raises the clear "not available" error
        source = open_catalog_source([path], cat_opts, crs=given, z_to_metres=False)
        with steps(f"Extracting the edges of {side} {label}"):
            run = run_job(catalog_features, source, cat_opts, wants_catalog([path], cat_opts),
                          kind="edges", classes=classes, source_id=source_id)
        failed_exit(run)
        if len(run.value) == 0:
            raise NothingToMeasureError(f"{side} {label}: no edges found")
        # matched with heights in metres (the job gives them back in the cloud's unit)
        return heights_in_metres(run.value)
    with steps(f"Reading {side} " + label) as progress:
        return heights_in_metres(load_segments(path, classes=classes, source_id=source_id,
                                               crs=given, progress=progress))


def _write_matrix(r: Any, path: Any) -> None:
    import numpy as np

    order = np.argsort(r.pair_test, kind="stable")
    pt, pm, dd = r.pair_test[order], r.pair_model[order], r.pair_d_tm[order]
    bounds = np.searchsorted(pt, np.arange(r.p + 1))
    with open(path, "w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["test_id", *[str(x) for x in r.model_ids.tolist()]])
        for i, tid in enumerate(r.test_ids.tolist()):
            row = [""] * r.q
            for j, v in zip(
                pm[bounds[i] : bounds[i + 1]].tolist(),
                dd[bounds[i] : bounds[i + 1]].tolist(),
                strict=True,
            ):
                row[j] = format_decimal(v)
            w.writerow([str(tid), *row])


def _write_pairs(r: Any, path: Any) -> None:
    import numpy as np

    keep = np.flatnonzero(r.match_tm | r.match_mt)
    with open(path, "w", encoding="utf-8", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["test_id", "model_id", "d_theta", "d_par", "d_perp", "d_tm", "d_mt",
                    "match_tm", "match_mt"])
        for k in keep.tolist():
            distances = [*r.pair_components[k], r.pair_d_mt[k]]  # d_theta .. d_tm, d_mt
            w.writerow([r.test_ids[r.pair_test[k]], r.model_ids[r.pair_model[k]],
                        *(format_decimal(float(d)) for d in distances),
                        *("true" if match[k] else "false" for match in (r.match_tm, r.match_mt))])


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path())
@click.option(
    "--by-source-id",
    is_flag=True,
    help="Each point_source_id (flight strip) of each cloud is a pass.",
)
@click.option(
    "--source-id",
    type=INT_LIST,
    default=None,
    help="With --by-source-id: only these strips, e.g. 4320,4330.",
)
@click.option(
    "--pool",
    is_flag=True,
    help="With --by-source-id: one pass per strip across all FILES (neighbouring tiles of one "
    "survey), so each strip pair is compared once over the whole block.",
)
@click.option(
    "--outlines",
    is_flag=True,
    help="Also use roof-plane outlines (stand-ins for roof-wall and step edges, which airborne "
    "scans leave without a wall plane): many more lines per strip pair on small tiles; on dense "
    "strips they can blur the automatic threshold.",
)
@click.option(
    "--steps/--no-steps",
    "step_edges",
    default=True,
    show_default=True,
    help="Also use step edges: straight roof boundaries where the surface next to the roof is "
    "at least 0.5 m lower or absent (thin walls airborne scans barely see).",
)
@click.option(
    "--auto-threshold",
    "auto",
    type=click.Choice(["sampling", "knee"]),
    default="sampling",
    show_default=True,
    help="With --by-source-id: 'sampling' keeps each pair's automatic threshold within "
    "[1.1, 2.0] x the sparser strip's point spacing (10th-neighbour distance), so tiles of "
    "one survey get the same answer; 'knee' is the plain knee of the nearest distances.",
)
@click.option(
    "--shared-threshold",
    is_flag=True,
    help="One automatic threshold for every pair: the median of the pairs' own automatic "
    "thresholds (passes of one survey get the same answer).",
)
@_matching_options
@catalog_options
@common_options
def repeatability(
    files: tuple[str, ...],
    by_source_id: bool,
    source_id: list[int] | None,
    pool: bool,
    outlines: bool,
    step_edges: bool,
    auto: str,
    shared_threshold: bool,
    weight: float,
    sensitivity: float,
    threshold: float | None,
    rotate: str,
    denominator: str,
    classes: list[int] | None,
    crs: str | None,
    **cat_opts: Any,
) -> None:
    """Compare every pair of passes both ways: a table like Poreba & Goulette's Table 1.

    Passes are FILES (segment files or clouds, all compared with each other), or with
    --by-source-id the flight strips of each cloud (compared within each file; with
    --pool, across all files: neighbouring tiles of a survey hold too few shared edges
    each for a stable automatic threshold). The final LHD of each pair is marked with *.

    With --by-source-id, FILES may be one cloud or a catalog (several clouds, a
    folder, a glob, a .vpc): the strips are then compared over the whole area by
    one job (a catalog's strip edges found chunk by chunk, an edge once, by its
    midpoint's chunk; one file is one region), so a file and a folder of its tiles
    give the same figures and the same JSON results: ``{"pairs": [rows],
    "strips": {strip: n_edges}, "catalog": {...}}``.
    """
    from ..accuracy.lines_io import is_segment_file, load_passes, pool_passes
    from ..errors import OptionError
    from ..tiling.jobs_lines import strip_pairs

    given = input_crs(crs)
    if source_id is not None and not by_source_id:
        raise OptionError("--source-id selects strips and needs --by-source-id")
    if pool and not by_source_id:
        raise OptionError("--pool joins the strips of several files and needs --by-source-id")
    # Several named files without catalog options keep the per-file (or --pool) comparison;
    # one cloud, a folder, a glob, a .vpc or any catalog option compares the strips over the
    # whole area through one job (one file is one region): the same code and JSON either way.
    named_files = len(files) > 1 and not catalog_options_given(cat_opts)
    one_cloud = len(files) == 1 and not is_segment_file(files[0])
    if by_source_id and (wants_catalog(files, cat_opts) or one_cloud) and not named_files:
        from ..tiling.jobs_api import catalog_repeatability

        if shared_threshold and threshold is not None:
            raise OptionError("--shared-threshold computes the threshold; do not also give "
                              "--threshold")
        if one_cloud and not catalog_options_given(cat_opts):
            cat_opts = {**cat_opts, "workers": 1}  # one region: in this process, no Dask
        match_options = {"weight": weight, "sensitivity": sensitivity, "threshold": threshold,
                         "rotate": rotate, "denominator": denominator, "auto": auto,
                         "shared_threshold": shared_threshold}
        prepare_outputs(inputs=tuple(files))
        source = open_catalog_source(files, cat_opts, crs=given, z_to_metres=False)
        run = run_job(catalog_repeatability, source, cat_opts, True, classes=classes,
                      source_id=source_id, match_options=match_options,
                      edge_options={"steps": step_edges, "outlines": outlines})
        extra: dict[str, Any] = run.extra  # the job's details
        if not run.value:
            raise OptionError(f"repeatability needs at least two strips with edges, got "
                              f"{len(extra['strips'])}")
        _print_rows(run.value, threshold, pool=True)
        strips = {str(k): len(v) for k, v in extra["strips"].items()}
        echo("  strips          " + ", ".join(f"{k} ({n} edges)" for k, n in strips.items()))
        finish_run("repeatability", run, True, inputs={"files": list(files)},
               parameters={"by_source_id": True, "source_id": source_id, "classes": classes,
                           **match_options, **extra["segment_options"],
                           **extra["edge_options"]},
               results={"pairs": run.value, "strips": strips}, cat_opts=cat_opts)
        return
    if catalog_options_given(cat_opts):
        raise OptionError("catalog options apply to repeatability --by-source-id only")
    prepare_outputs(inputs=files)
    steps = Steps()
    with steps("Reading passes and extracting edges") as progress:
        passes = load_passes(
            list(files),
            by_source_id=by_source_id,
            classes=classes,
            source_id=source_id,
            crs=given,
            progress=progress,
            edge_options={"outlines": outlines, "steps": step_edges},
        )
    if pool:
        passes = pool_passes(passes)
    # pairs within a group (one file, or every pass), in the order the passes came
    todo = [(i, j) for i, j in combinations(range(len(passes)), 2)
            if passes[i][0] == passes[j][0]]
    if not todo:
        raise OptionError(
            f"repeatability needs at least two passes, got {len(passes)}"
            + ("" if by_source_id else " (use --by-source-id for the strips of one file)")
        )
    with steps(f"Matching {len(todo)} pass pair(s)"):
        matched = strip_pairs(dict(enumerate(p[2] for p in passes)), pairs=todo,
                              shared_threshold=shared_threshold,
                              auto=auto if by_source_id else "knee", weight=weight,
                              sensitivity=sensitivity, threshold=threshold, rotate=rotate,
                              denominator=denominator)
    rows: list[dict] = []
    for (i, j), row in zip(todo, matched, strict=True):
        group = passes[i][0]
        rows.append({**({"file": group} if group else {}), **row,
                     "test": passes[i][1], "model": passes[j][1]})
    if shared_threshold:  # the median knee every pair was matched with
        threshold = next((r["threshold_tm"] for r in rows if "error" not in r), None)
        echo(f"shared threshold δ = {threshold:.3f} m: median of the pair thresholds")
    _print_rows(rows, threshold, pool=pool)
    if rows and all("error" in r for r in rows):
        # Nothing to measure is an error (exit 1), never a table of n/a with exit 0.
        from ..errors import NothingToMeasureError

        raise NothingToMeasureError(
            f"none of the {len(rows)} pair(s) of passes could be compared (reasons above)"
        )
    finish(
        "repeatability",
        inputs={"files": list(files)},
        parameters={
            "by_source_id": by_source_id,
            "source_id": source_id,
            "pool": pool,
            "weight": weight,
            "sensitivity": sensitivity,
            "threshold": threshold,
            "shared_threshold": shared_threshold,
            "outlines": outlines,
            "steps": step_edges,
            "auto_threshold": auto if by_source_id and threshold is None else None,
            "rotate": rotate,
            "denominator": denominator,
            "classes": classes,
            "crs": crs,
        },
        results=rows,
    )


def _print_rows(rows: list[dict], threshold: float | None, *, pool: bool = False) -> None:
    """The repeatability table on stdout."""
    width = max([28] + [len(_row_name(r)) + 2 for r in rows])
    head = (
        f"{'Data sets':<{width}}{'p':>6}{'q':>6}{'pairs T→M':>11}{'pairs M→T':>11}"
        f"{'δ T→M':>9}{'δ M→T':>9}"
        f"{'OLHD T→M':>11}{'OLHD M→T':>11}"
    )
    echo(head)
    echo("-" * len(head))
    fallback = False
    for row in rows:
        name = _row_name(row)
        if "error" in row:
            echo(f"{name:<{width}}  {row['error']}")
            continue
        o1, o2, lhd = row["olhd_tm"], row["olhd_mt"], row["lhd"]
        s1 = "*" if o1 is not None and o1 == lhd else " "
        s2 = "*" if o2 is not None and o2 == lhd and s1 == " " else " "
        f1 = "" if row["threshold_found_tm"] or threshold is not None else "!"
        f2 = "" if row["threshold_found_mt"] or threshold is not None else "!"
        fallback |= bool(f1 or f2)
        echo(
            f"{name:<{width}}{row['p']:>6}{row['q']:>6}{row['n_pairs_tm']:>11}{row['n_pairs_mt']:>11}"
            f"{fmt_number(row['threshold_tm'], 3) + f1:>9}"
            f"{fmt_number(row['threshold_mt'], 3) + f2:>9}"
            f"{fmt_number(o1, 3) + s1:>11}{fmt_number(o2, 3) + s2:>11}"
        )
    echo(
        "* final modified LHD of the pair"
        + ("; ! threshold fell back (no knee found)" if fallback else "")
    )
    few = [r for r in rows if "error" not in r and min(r["p"], r["q"]) < _FEW_SEGMENTS]
    if threshold is None and few and not pool:
        # A knee among a handful of nearest distances is a guess: on the IGN 50 m tiles
        # (10-20 edges per strip) it ranged from 0.10 to 0.82 m between neighbouring tiles.
        echo(
            f"note: {len(few)} pair(s) with fewer than {_FEW_SEGMENTS} segments on a side: their "
            "automatic thresholds are unstable; use --pool (tiles of one survey), "
            "--shared-threshold or --threshold"
        )


#: Fewer segments than this on either side of a pair: the automatic threshold is flagged.
_FEW_SEGMENTS = 30


def _row_name(row: dict) -> str:
    prefix = f"{row['file']}: " if row.get("file") else ""
    return f"{prefix}{row['test']} - {row['model']}"
