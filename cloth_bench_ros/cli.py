"""`cloth-bench`: the command-line front door (run, trajectory, engines, bag)."""

from __future__ import annotations

import argparse
import logging
import sys
import warnings
from pathlib import Path

from cloth_bench_ros.trajectory import PRIMITIVES


class UserError(Exception):
    """Bad input from the user: printed as one line, exit status 2."""


def _rate(text: str) -> float:
    try:
        rate = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"rate {text!r} is not a number") from None
    if not rate > 0 or rate == float("inf"):
        raise argparse.ArgumentTypeError(f"rate must be > 0 Hz, got {text}")
    return rate


def check_bag(bag: Path) -> None:
    """Fail early, with one line, on a bag that has no readable PointCloud2 frame."""
    from cloth_bench_ros.data.bag import BagReader

    reader = BagReader(bag)
    topic = reader.cloud_topic()
    if next(reader.raw_messages([topic]), None) is None:
        raise UserError(f"bag {bag}: no PointCloud2 message on {topic} could be read")


def cmd_run(args: argparse.Namespace) -> int:
    from cloth_bench_ros.engines import engine_class
    from cloth_bench_ros.engines.presets import CLOTHS
    from cloth_bench_ros.paths import bundled_bag
    from cloth_bench_ros.pipeline import RunConfig, run_pipeline
    from cloth_bench_ros.report import result_table

    engines = args.engine or ["mujoco"]
    for name in engines:
        engine_class(name)
    if args.cloth not in CLOTHS:
        raise UserError(f"unknown cloth {args.cloth!r} (valid: {', '.join(CLOTHS)})")
    bag = Path(args.bag) if args.bag else bundled_bag(args.cloth, args.primitive)
    check_bag(bag)
    out = Path(args.output) if args.output else Path("results") / f"{args.cloth}_{args.primitive}_{int(args.rate)}hz_seed{args.seed}"
    config = RunConfig(bag=bag, engines=engines, rate_hz=args.rate, cloth=args.cloth, primitive=args.primitive,
                       seed=args.seed, pacing=args.pacing, output_dir=out)
    summary = run_pipeline(config)
    print(f"cloth-bench run: {args.cloth} {args.primitive} at {args.rate:g} Hz, seed {args.seed}, bag {bag}")
    print(result_table(summary))
    real = summary["real"]
    print(f"real frames: {real['frames']} ({real['empty_frames_skipped']} empty skipped, "
          f"{real['nan_points_dropped']} NaN points dropped, {real['unpaired_frames']} unpaired)")
    print(f"report: {out}/summary.json, {out}/frames.csv")
    return 0


def cmd_trajectory(args: argparse.Namespace) -> int:
    from cloth_bench_ros.trajectory import sample_quintic, to_csv

    sys.stdout.write(to_csv(sample_quintic(args.primitive, args.rate)))
    return 0


def cmd_engines(args: argparse.Namespace) -> int:
    from cloth_bench_ros.engines import known_engines

    print(f"{'engine':<10} {'available':<10} {'version':<10} reason")
    for info in known_engines():
        print(f"{info.name:<10} {'yes' if info.available else 'no':<10} {info.version or '-':<10} {info.reason}")
    return 0


def cmd_bag_info(args: argparse.Namespace) -> int:
    from cloth_bench_ros.data.bag import describe

    print(describe(Path(args.path)))
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (the usage is in --help)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _read_transform(path: str):
    """A 4x4 matrix from a .npy file or a text file of 16 numbers (spaces, commas or newlines)."""
    import numpy as np

    try:
        if path.endswith(".npy"):
            values = np.load(path).astype(float).ravel()
        else:
            values = np.array([float(x) for x in Path(path).read_text().replace(",", " ").split()])
    except (OSError, ValueError) as exc:
        raise UserError(f"transform {path}: cannot be read ({exc})") from None
    if values.size != 16 or not np.isfinite(values).all():
        raise UserError(f"transform {path}: needs 16 finite numbers (a 4x4 matrix), found {values.size}")
    return values.reshape(4, 4)


def cmd_import(args: argparse.Namespace) -> int:
    from cloth_bench_ros.data.importer import import_dataset

    transform = _read_transform(args.transform) if args.transform else None
    bags = import_dataset(Path(args.root), Path(args.out), transform=transform, progress=not args.quiet,
                          overwrite=args.overwrite)
    for bag in bags:
        print(bag)
    print(f"imported {len(bags)} trial(s) into {args.out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="cloth-bench", description="Sim-to-real benchmark of cloth simulators.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log the nodes' messages")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="run the node graph on a bag and print the result table")
    run.add_argument("--engine", action="append", help="engine to run (repeat for several; default mujoco)")
    run.add_argument("--rate", type=_rate, default=100.0, help="simulator rate in Hz (default 100)")
    run.add_argument("--cloth", default="towel", help="towel, chequered or linen (default towel)")
    run.add_argument("--primitive", default="dynamic", choices=PRIMITIVES, help="default dynamic")
    run.add_argument("--bag", help="rosbag2 MCAP bag to score against (default: the bundled one)")
    run.add_argument("--seed", type=int, default=0, help="perturbs the initial cloth (default 0)")
    run.add_argument("--pacing", default="lockstep", choices=("lockstep", "realtime"))
    run.add_argument("--output", help="report directory (default results/<cloth>_<primitive>_<rate>hz_seed<seed>)")
    run.set_defaults(func=cmd_run)

    traj = sub.add_parser("trajectory", help="print the quintic part of a primitive as CSV")
    traj.add_argument("--primitive", default="dynamic", choices=PRIMITIVES)
    traj.add_argument("--rate", type=_rate, default=100.0)
    traj.set_defaults(func=cmd_trajectory)

    engines = sub.add_parser("engines", help="list known engines, their availability and version")
    engines.set_defaults(func=cmd_engines)

    imp = sub.add_parser("import", help="turn the published dataset (PLY/PCD per frame) into one bag per trial")
    imp.add_argument("root", help="dataset root: <root>/<cloth>_rag_<trial>/<primitive>/cloud/<NNNNN>.ply|.pcd")
    imp.add_argument("--out", required=True, help="directory for the bags")
    imp.add_argument("--transform", help="4x4 matrix into the simulation frame (text file of 16 numbers, or .npy)")
    imp.add_argument("--overwrite", action="store_true", help="replace bags that exist")
    imp.add_argument("--quiet", action="store_true", help="no progress bar")
    imp.set_defaults(func=cmd_import)

    bag = sub.add_parser("bag", help="bag tools")
    bag_sub = bag.add_subparsers(dest="bag_command", required=True, parser_class=_Parser)
    info = bag_sub.add_parser("info", help="describe a bag: topics, frames, trial metadata")
    info.add_argument("path")
    info.set_defaults(func=cmd_bag_info)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s")
    warnings.formatwarning = lambda message, *_: f"cloth-bench: warning: {message}\n"
    from cloth_bench_ros.data.bag import BagError

    try:
        return args.func(args)
    except (UserError, ValueError, OSError, BagError) as exc:
        print(f"cloth-bench: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
