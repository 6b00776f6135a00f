"""hrg-damping on sim-hrg-acutronic (the Acutrol driver and simulator, tcp framing) gives the same
numbers, to the bit, as on sim-hrg (the Modbus table): the table's protocol must not reach the
gyro's physics."""

from __future__ import annotations

from procedures.hrg_damping import HrgDamping

PARAMS = {"rate_dps": 20.0, "record_s": 20.0, "stream_hz": 200.0, "compensate": False}


def _measurements(station_name: str, tmp_path) -> dict[str, tuple]:
    from bench.composition.sim_station import SimStation
    from bench.engine import Runner
    from bench.results import ResultsStore

    station = SimStation(station_name, seed=0).open()
    store = ResultsStore(tmp_path / f"{station_name}.sqlite")
    try:
        record = Runner(station, runs_dir=tmp_path / station_name, store=store).run(HrgDamping, PARAMS)
    finally:
        store.close()
        station.close()
    assert record.outcome == "COMPLETE", record.end_reason
    return {m.name: (m.value, m.ci95) for m in record.measurements}


def test_hrg_damping_on_sim_hrg_acutronic_is_bit_identical_to_sim_hrg(tmp_path):
    acutrol = _measurements("sim-hrg-acutronic", tmp_path)
    modbus = _measurements("sim-hrg", tmp_path)
    assert acutrol and acutrol == modbus
