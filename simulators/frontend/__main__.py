"""Serve a simulated front end as its own process: `python -m simulators.frontend [--preset mems]
[--speed 100] [--port 0] [--seed 0]`.  Prints the VISA resource name, serves until stdin closes
or Ctrl-C.  The world runs in real time at `speed` x the wall clock (a SimClock thread)."""

from __future__ import annotations

import argparse
import sys

from bench.clock import SimClock
from simulators.physics.params import preset
from simulators.world import World

from . import serve_frontend


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m simulators.frontend", description=__doc__)
    ap.add_argument("--preset", default="mems")
    ap.add_argument("--speed", type=float, default=1.0, help="virtual seconds per wall second")
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--adc-noise-v", type=float, default=1e-4)
    args = ap.parse_args(argv)
    world = World(preset(args.preset), seed=args.seed)
    clock = SimClock(world, speed=args.speed)
    server = serve_frontend(world, port=args.port, seed=args.seed, adc_noise_v=args.adc_noise_v)
    print(server.resource_name, flush=True)
    try:
        sys.stdin.read()
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
        clock.close()


if __name__ == "__main__":
    main()
