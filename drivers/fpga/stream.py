"""The FPGA stream's declared columns, the loops' saturation bits and the output modes: what
procedures, reports and the station entry read of the FPGA (docs/fpga_link.md), without the frame
codec's compiled kernels (numba), so a report, `gyrobench list` or a station check does not import
numba (issue 36).  drivers.fpga.protocol re-exports every name here."""

from __future__ import annotations

from bench.streams import Column, StreamSchema, declare

# --- output modes (register OUTPUT_MODE, docs/fpga_link.md "Output modes") --------------------
MODE_WHOLE_ANGLE = 0  # rate-integrating: the wave turns freely (WHOLE_ANGLE adds a precession command)
MODE_FORCE_TO_REBALANCE = 1  # rate: a rebalance loop holds the wave at FTR_ANGLE_DEG; its force is the output
OUTPUT_MODES = {"whole-angle": MODE_WHOLE_ANGLE, "force-to-rebalance": MODE_FORCE_TO_REBALANCE}

# --- loop saturation bits (a stream frame's address field; the stream's sat_flags column) -----
#: a loop force held at FORCE_LIMIT over the frame's block: the loop is not doing what it is asked
SAT_AMP = 0x1  # amplitude (AGC, or the open-loop DRIVE_FORCE)
SAT_QUAD = 0x2  # quadrature loop
SAT_PREC = 0x4  # whole-angle precession force (a precession command above FORCE_LIMIT / (4 a))
SAT_FTR = 0x8  # force-to-rebalance loop (a rate above its range)
SAT_NAMES = {SAT_AMP: "amplitude (AGC)", SAT_QUAD: "quadrature", SAT_PREC: "precession", SAT_FTR: "rebalance"}


def saturation_text(flags: int) -> str:
    """The loops a sat_flags value names, e.g. 'precession, quadrature'."""
    return ", ".join(name for bit, name in SAT_NAMES.items() if int(flags) & bit) or "none"


#: the FPGA stream: sample index and time, the four slow variables (amplitude units, as the AGC
#: setpoint) and the four loop outputs (forces in 1/s per unit amplitude, the PLL's offset in Hz)
STREAM_SCHEMA = declare(StreamSchema("fpga", "fpga", (
    Column("index", "1", "u8", doc="sample number since the FPGA started"),
    Column("t_s", "s", doc="time of the sample (bench clock)", quantity="time t"),
    Column("cx", "1", "f4", quantity="slow variable cx"), Column("sx", "1", "f4", quantity="slow variable sx"),
    Column("cy", "1", "f4", quantity="slow variable cy"), Column("sy", "1", "f4", quantity="slow variable sy"),
    Column("amp_ctrl", "1/s", "f4", doc="amplitude (AGC) force", quantity="amplitude control"),
    Column("freq_ctrl", "Hz", "f4", doc="reference frequency minus REF_FREQ_HZ", quantity="frequency control"),
    Column("quad_ctrl", "1/s", "f4", doc="quadrature force", quantity="quadrature control"),
    Column("prec_ctrl", "1/s", "f4", doc="whole-angle precession force (the rebalance force in force-to-rebalance)",
           quantity="precession control"),
    Column("angle_out_deg", "deg", "f8", doc="wave angle in the case frame, unwrapped (whole-angle output)",
           quantity="wave angle output"),
    Column("rate_out_dps", "deg/s", "f4", doc="force-to-rebalance rate output G degrees(F_p / (4 a_set)); 0 otherwise",
           quantity="rate output"),
    Column("sat_flags", "1", "u2", doc="loops whose force was held at FORCE_LIMIT over the frame's block: bits "
           "1 amplitude (AGC), 2 quadrature, 4 precession, 8 rebalance (0: none saturated)",
           quantity="loop saturation"),
)))
STREAM_COLUMNS = STREAM_SCHEMA.names
