"""`gyrobench design`: the table rate and record length a damping or free-decay run needs."""

from __future__ import annotations

import argparse
import math

from .common import EXIT_OK, EXIT_USAGE, _err


def add_parser(sub) -> None:
    """Register `design` and its options."""
    design = sub.add_parser("design", help="experiment design: table rate and record length for a procedure")
    design.add_argument("procedure", choices=["hrg-damping", "hrg-free-decay"])
    design.add_argument("--preset", default="hrg", help="resonator preset giving the defaults below")
    design.add_argument("--tau-s", type=float, default=None)
    design.add_argument("--delta-inv-tau-per-s", type=float, default=None)
    design.add_argument("--noise-sigma", type=float, default=None, help="white noise per channel per FPGA sample")
    design.add_argument("--sample-hz", type=float, default=1000.0, help="the FPGA's sample rate (the station's)")
    design.add_argument("--stream-hz", type=float, default=None, help="fitted sample rate (default: the procedure's)")
    design.add_argument("--bryan-factor", type=float, default=None)
    design.add_argument("--split-hz", type=float, default=None)
    design.add_argument("--quadrature", type=float, default=0.0, help="quadrature k left at the cut (amplitude 1)")
    design.add_argument("--model", choices=["exact", "patent"], default="exact", help="energy model of the fit")
    design.set_defaults(func=cmd)


def cmd(args: argparse.Namespace) -> int:
    """Design the run the procedure will make: its stream rate (boxcar-decimated from the FPGA's
    sample rate, which sets the noise per fitted sample), then table rate and record length."""
    from bench.analysis.damping_design import design_hrg_damping, design_hrg_free_decay
    from bench.composition import simulated_unit
    from procedures.hrg_damping import HrgDamping
    from procedures.hrg_free_decay import HrgFreeDecay

    proc = {"hrg-damping": HrgDamping, "hrg-free-decay": HrgFreeDecay}[args.procedure]
    try:
        p = simulated_unit(args.preset)
        stream_hz = args.stream_hz if args.stream_hz is not None else float(proc.stream_hz.default)
        if not 0 < stream_hz <= args.sample_hz:
            raise ValueError(f"--stream-hz {stream_hz:g} must be in (0, --sample-hz {args.sample_hz:g}]")
        noise = args.noise_sigma if args.noise_sigma is not None else p.noise_sigma
        kw = dict(
            tau_s=args.tau_s if args.tau_s is not None else p.tau_s,
            delta_inv_tau_per_s=(
                args.delta_inv_tau_per_s if args.delta_inv_tau_per_s is not None else p.delta_inv_tau_per_s
            ),
            noise_sigma=noise * math.sqrt(stream_hz / args.sample_hz),  # boxcar mean of sample_hz/stream_hz samples
            stream_hz=stream_hz,
            bryan_factor=args.bryan_factor if args.bryan_factor is not None else p.bryan_factor,
            split_hz=args.split_hz if args.split_hz is not None else p.split_hz,
            quadrature=args.quadrature,
            theta_tau_deg=p.theta_tau_deg,
            theta_w_deg=p.theta_w_deg,
        )
        if args.procedure == "hrg-damping":
            design = design_hrg_damping(model=args.model, lengths_tau=(0.25, 0.5, 1.0, 2.0, 3.0), **kw)
        else:
            design = design_hrg_free_decay(**kw)
    except ValueError as exc:  # a bad value, or no preset by that name (ParameterError)
        _err(str(exc))
        return EXIT_USAGE
    print(design.summary())
    if args.procedure == "hrg-damping":
        r = design.recommended
        print(f"  run it: gyrobench run hrg-damping --set rate_dps={r.rate_dps:.4g} --set record_s={r.duration_s:.0f} "
              f"--set stream_hz={stream_hz:g} --set fit_model={args.model}")
    return EXIT_OK
