"""The driver on a true GPIB resource name (`GPIB0::1::INSTR`, framing chosen by the transport)
through pyvisa-sim, which plays a transcript written from TM-8004's examples
(tests/acutrol_gpib_transcript.yaml): the GPIB code path without GPIB hardware or library."""

from __future__ import annotations

from pathlib import Path

from bench.clock import SimClock
from drivers.rate_table.acutronic_driver import AcutrolRateTable
from simulators.physics.params import preset
from simulators.world import World
from tests.needs import need
from tests.test_rate_table import LIMITS

TRANSCRIPT = Path(__file__).with_name("acutrol_gpib_transcript.yaml")


def test_a_gpib_resource_speaks_lines_with_esr_and_goes_to_local():
    import importlib.util

    need(importlib.util.find_spec("pyvisa_sim") is not None, "pyvisa-sim (gyrobench[dev]) is not installed")
    clock = SimClock(World(preset("hrg"), seed=1))
    table = AcutrolRateTable(resource="GPIB0::1::INSTR", visa_library=f"{TRANSCRIPT}@sim", limits=LIMITS,
                             clock=clock, vtrip_dps=550.0, timeout_s=1.0)  # fmt: skip
    try:
        assert table.framing == "gpib"
        table.connect()  # every line of the connect sequence must be in the transcript, answered 0
        assert table.idn.startswith("Acutronic R&D USA,Acutrol3000") and table.units == "deg"
        st = table.status()
        assert st.angle_deg == 12.5 and st.interlock_open and not st.estop and not st.enabled
        table.stop()  # *ESR? = 8: all axis profiles complete (the ACT2000 table), not an error
    finally:
        table.close()
        clock.close()
