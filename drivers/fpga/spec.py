"""The station entry of the FPGA register link and demodulated stream (`driver = "fpga-link"`):
its keys, build, health (link alive, no frame lost since the run's stream began), its stream and
its safe-state part (it cuts the drive)."""

from __future__ import annotations

from typing import Any

from bench.devices import DriverSpec, Key, StreamSpec, register_driver
from drivers.errors import DeviceError, LinkLostError

from .stream import OUTPUT_MODES, STREAM_COLUMNS  # not .protocol: its frame kernels import numba


def _build(cfg: dict[str, Any], clock: Any) -> Any:
    from .link import FpgaLink

    link = FpgaLink(cfg["url"], clock=clock, timeout_s=cfg["timeout_s"])
    link.connect()
    try:  # the station's output mode, hold angle and rate-output gain, written at connect
        link.set_output_mode(cfg["output_mode"], ftr_angle_deg=cfg["ftr_angle_deg"], ftr_gain=cfg["ftr_gain"])
        for key, register in LOOP_KEYS.items():  # a resonator far from the firmware's defaults (a MEMS ring)
            if cfg.get(key):
                link.write_register(register, float(cfg[key]))
    except BaseException:
        link.close()
        raise
    return link


#: station keys for the loops' limit and gains (0: the firmware's own), written at connect: a MEMS
#: ring decays in ~50 ms and has a split of Hz where the HRG's loops are set for minutes and mHz
LOOP_KEYS = {"force_limit": "FORCE_LIMIT", "agc_kp": "AGC_KP", "agc_ki": "AGC_KI", "pll_kp": "PLL_KP",
             "pll_ki": "PLL_KI", "quad_kp": "QUAD_KP", "quad_ki": "QUAD_KI", "ftr_kp": "FTR_KP", "ftr_ki": "FTR_KI"}


def _counters(link: Any) -> tuple[int, int, int]:
    """Frames dropped, frames corrupt, blocks a subscriber failed on: the counts a run compares."""
    s = link.stats
    return (s.dropped, s.corrupt, s.callback_errors)


def _health(link: Any, since: tuple[int, int, int] | None = None) -> None:
    """Lost link, or a frame lost or rejected since the run's stream began (`since`), is a link fault."""
    if not link.connected:
        raise LinkLostError(f"FPGA link {link.url} lost")
    if getattr(link.clock, "lockstep", False):
        # lockstep: the world waits while the stream catches up to the bench clock, so a
        # link that died is found at this check's simulated time, not whenever the reader
        # thread happens to notice (a real bench's FPGA clock is not the bench's: skipped)
        link.sync(timeout_wall_s=max(1.0, 2.0 * getattr(link, "timeout_s", 1.0)))
    if since is None:  # no run stream started: nothing to compare against yet
        return
    s = link.stats
    if s.dropped > since[0] or s.corrupt > since[1]:
        raise LinkLostError(
            f"FPGA link {link.url}: stream frames lost ({s.dropped - since[0]}) or corrupt ({s.corrupt - since[1]})"
        )
    if s.callback_errors > since[2]:  # the recorder (or a procedure's tap) failed on a block
        raise DeviceError(
            f"FPGA stream: {s.callback_errors - since[2]} block(s) not taken by a subscriber (recorder?); "
            "the raw data would be incomplete"
        )


def _start_stream(link: Any, cfg: dict[str, Any]) -> None:
    link.start_stream(cfg["decimation"])


def _stop_stream(link: Any, clock: Any) -> None:
    """Let the stream reach the bench clock's time (nothing recorded is cut short), then stop it."""
    if link.connected:
        link.wait_for_sample(float(clock.now()), timeout_wall_s=5.0)
        link.stop_stream()


SPEC = register_driver(
    DriverSpec(
        name="fpga-link",
        role="fpga",
        part="drive-cut",
        keys={
            "driver": Key(str, required=True),
            "url": Key(str, "", doc="serial port or pyserial URL"),
            "nvm_file": Key(str, "", doc="simulated FPGA only: file of its NVM (empty: kept with the World)"),
            "timeout_s": Key(float, 1.0, 0.01, 30.0, doc="wall time allowed for a reply", unit="s"),
            "decimation": Key(int, 1, 1, 100000, doc="stream every Nth sample"),
            "output_mode": Key(str, "whole-angle", choices=tuple(OUTPUT_MODES),
                               doc="whole-angle (rate-integrating: the output is the wave angle) or "
                                   "force-to-rebalance (rate: the wave held, the rebalance force is the output)"),
            "ftr_angle_deg": Key(float, 0.0, -45.0, 45.0, unit="deg",
                                 doc="force-to-rebalance: the wave angle the rebalance loop holds"),
            "ftr_gain": Key(float, 1.0, -1e6, 1e6,
                            doc="force-to-rebalance rate-output gain G (scale factor G K, K the Bryan factor)"),
            **{k: Key(float, 0.0, 0.0, 1e4, doc=f"{r} written at connect (0: the firmware's own)")
               for k, r in LOOP_KEYS.items()},
        },
        build=_build,
        serve="simulators.fpga.server:serve_station",
        health=_health,
        stream=StreamSpec(tuple(STREAM_COLUMNS), start=_start_stream, stop=_stop_stream, counters=_counters),
        doc="FPGA register link and demodulated stream",
    )
)
