"""The `gyrobench` command line."""

from __future__ import annotations

import argparse
import sys


def _cmd_demo(args: argparse.Namespace) -> int:
    from bench.demo import run_decay_demo

    run_decay_demo(seed=args.seed, rate_dps=args.rate_dps, duration_s=args.duration_s)
    return 0


def _add_gui(sub) -> None:
    from bench.gui.cli_args import add_gui_subcommand

    add_gui_subcommand(sub)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="gyrobench", description="Calibrate Coriolis vibratory gyroscopes.")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="simulated HRG free decay on a spinning table, with a summary")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--rate-dps", type=float, default=500.0)
    demo.add_argument("--duration-s", type=float, default=300.0)
    demo.set_defaults(func=_cmd_demo)
    _add_gui(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
