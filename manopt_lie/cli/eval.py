"""``manopt-lie eval ape|rpe REF EST``: trajectory errors as evo computes them (``evo_ape``,
``evo_rpe``), on TUM, KITTI or g2o files (:mod:`manopt_lie.problems.trajectory_io`,
:mod:`manopt_lie.problems.evaluation`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from manopt_lie.problems import evaluation
from manopt_lie.problems import trajectory_io as tio

from . import _common

RELATIONS = "; ".join(f"{k}: {what}" + (f" ({unit})" if unit else "") for k, (what, unit) in
                      evaluation.RELATIONS.items())  # fmt: skip


def add_parser(commands: Any) -> None:
    evaluate = commands.add_parser(
        "eval", help="trajectory errors (APE, RPE) against a reference, as evo computes them",
        description="Compare an estimated trajectory with a reference: absolute pose error (ape) or relative pose "
        "error (rpe), with the statistics rmse, mean, median, std, min, max and sse, as evo_ape and evo_rpe compute "
        "them (Umeyama alignment, evo's pose relations and timestamp association).",
    )  # fmt: skip
    metrics = evaluate.add_subparsers(dest="metric", required=True, metavar="{ape,rpe}",
                                      parser_class=_common.Parser)  # fmt: skip
    ape = metrics.add_parser(
        "ape", help="absolute pose error: E_i = P_i⁻¹ Q_i per pose (estimate P, reference Q)",
        description="Absolute pose error E_i = P_i⁻¹ Q_i of every matched pose (estimate P, reference Q), after the "
        "alignment asked for: the global consistency of a trajectory. Like evo_ape.",
    )  # fmt: skip
    _common_flags(ape)
    ape.set_defaults(run=run)
    rpe = metrics.add_parser(
        "rpe", help="relative pose error over pairs Δ frames apart: the drift",
        description="Relative pose error E_ij = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j) over pairs (i, j) of matched poses Δ frames "
        "apart — (0, Δ), (Δ, 2Δ), … or, with --all-pairs, every (i, i + Δ): the local drift. Like evo_rpe.",
    )  # fmt: skip
    rpe.add_argument("-d", "--delta", type=_common.number(int, positive=True), default=1, metavar="N",
                     help="the pairs' distance in frames (default: %(default)s)")
    rpe.add_argument("--all-pairs", action="store_true", help="every pair (i, i + N), not only consecutive ones")
    _common_flags(rpe)
    rpe.set_defaults(run=run)


def _common_flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("reference", type=Path, metavar="REF", help="the reference (ground-truth) trajectory")
    parser.add_argument("estimate", type=Path, metavar="EST", help="the estimated trajectory")
    parser.add_argument("--format", choices=tio.FORMATS,
                        help="the files' format: tum (t x y z qx qy qz qw), kitti (12 numbers: [R t] row-major) or "
                        "g2o (its VERTEX poses, matched by id) (default: from the extension, else 8 numbers a line: "
                        "tum, 12: kitti)")
    parser.add_argument("-r", "--pose-relation", choices=tuple(evaluation.RELATIONS), default="trans_part",
                        metavar="RELATION", help=f"what of E is measured: {RELATIONS} (default: %(default)s)")
    parser.add_argument("-a", "--align", action="store_true",
                        help="align the estimate to the reference first (Umeyama, SE(3); Sim(3) with -s)")
    parser.add_argument("-s", "--correct-scale", action="store_true",
                        help="correct the scale: with -a fit a Sim(3) (evo_ape -as); alone, only the scale")
    parser.add_argument("--align-origin", action="store_true",
                        help="move the estimate's first pose onto the reference's")
    parser.add_argument("--t-max-diff", type=_common.number(float, positive=False), default=evaluation.MAX_DIFF,
                        metavar="SECONDS", help="largest timestamp difference of matched poses (default: %(default)s)")
    parser.add_argument("--t-offset", type=float, default=0.0, metavar="SECONDS",
                        help="added to the estimate's timestamps before matching (default: %(default)s)")
    parser.add_argument("--plot", type=Path, metavar="FIG.png",
                        help="the path coloured by the error, and the error over time (.png, .pdf or .svg)")
    parser.add_argument("--save-results", type=Path, metavar="RESULTS.json", help="write the JSON document")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of the text")


def _read(path: Path, fmt: str | None, what: str) -> tuple[tio.Trajectory, str]:
    if path.is_dir():
        raise _common.UsageError(f"{what} {path} is a directory, not a trajectory file")
    if not path.is_file():
        raise _common.UsageError(f"no such file: {path}")
    fmt = fmt or tio.sniff(path)
    return tio.read(path, fmt), fmt


def _match(ref: tio.Trajectory, est: tio.Trajectory, args: argparse.Namespace) -> tuple[tio.Trajectory, ...]:
    """The matched poses: by timestamp when both files have them (TUM, g2o ids), else by index."""
    if ref.stamps is not None and est.stamps is not None:
        i_ref, i_est = evaluation.associate(ref.stamps, est.stamps, max_diff=args.t_max_diff, offset=args.t_offset)
        return ref.subset(i_ref), est.subset(i_est)
    if ref.n != est.n:
        raise _common.UsageError(
            f"without timestamps (KITTI) poses are matched by index, but {args.reference} has {ref.n} poses and "
            f"{args.estimate} has {est.n}"
        )
    return ref, est


def run(args: argparse.Namespace) -> int:
    _common.figure_path(args.plot, "--plot", inputs=[args.reference, args.estimate])
    _common.output_path(args.save_results, "--save-results", inputs=[args.reference, args.estimate])
    if args.align_origin and (args.align or args.correct_scale):
        raise _common.UsageError("--align-origin cannot be combined with --align or --correct-scale")
    ref_all, ref_format = _read(args.reference, args.format, "REF")
    est_all, _ = _read(args.estimate, args.format, "EST")
    ref, est = _match(ref_all, est_all, args)
    if ref.d != est.d:
        ref, est = ref.lift(), est.lift()
    options = {"relation": args.pose_relation, "align": args.align, "correct_scale": args.correct_scale,
               "align_origin": args.align_origin}  # fmt: skip
    if args.metric == "ape":
        result = evaluation.ape(ref.poses, est.poses, **options)
    else:
        result = evaluation.rpe(ref.poses, est.poses, delta=args.delta, all_pairs=args.all_pairs, **options)
    document = {
        "reference": str(args.reference), "estimate": str(args.estimate), "reference_poses": ref_all.n,
        "estimate_poses": est_all.n, "matched": ref.n, **result.to_json(), "written": [],
    }  # fmt: skip
    if args.plot is not None:
        aligned = result.alignment.apply(est.poses.as_matrix())
        d = ref.d
        at = None if result.pairs is None else result.pairs[:, 1]
        times = ref.stamps if ref_format == "tum" else None  # seconds; g2o stamps are vertex ids
        from manopt_lie.bench import plots  # matplotlib: loaded only for a figure

        plots.pose_errors(ref.positions, aligned[:, :d, d], result.errors, args.plot, title=result.title,
                          unit=result.unit, stats=result.stats.to_json(), times=times, at=at)  # fmt: skip
        document["written"].append(str(args.plot))
    if args.save_results is not None:
        _common.write_text(args.save_results, _common.json_text(document, indent=1))
        document["written"].append(str(args.save_results))
    if args.json:
        _common.print_json(document)
        return _common.EXIT_OK
    print(result.title)
    what = "pairs" if args.metric == "rpe" else "poses"
    print(f"{result.errors.size} {what} compared ({ref.n} matched poses; {args.reference.name}: {ref_all.n}, "
          f"{args.estimate.name}: {est_all.n})")
    if result.alignment.method in ("sim", "scale"):
        print(f"scale correction: {result.alignment.scale:.6g}")
    print()
    width = max(len(k) for k in document if k in result.stats.to_json())
    for key, value in result.stats.to_json().items():
        print(f"  {key:>{width}}  {value:.6g}")
    for path in document["written"]:
        print(f"wrote {path}")
    return _common.EXIT_OK
