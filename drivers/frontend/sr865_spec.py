"""The station entry of the two-SR865 front end (`driver = "sr865-pair-frontend"`): its keys, how
to build it, its health and safe-state part; bench.devices finds and imports this module."""

from __future__ import annotations

from typing import Any

from bench.devices import DriverSpec, Key, StationError, register_driver


def _build(cfg: dict[str, Any], clock: Any) -> Any:
    from .sr865_pair import Sr865Limits, Sr865PairFrontEnd

    if not cfg["resource2"]:
        raise StationError("[devices.frontend] resource2: the second lock-in's VISA resource is missing")
    fe = Sr865PairFrontEnd(
        cfg["resource"],
        cfg["resource2"],
        clock=clock,
        limits=Sr865Limits(max_amplitude_v=cfg["max_amplitude_v"]),
        timeout_s=cfg["timeout_s"],
        instrument_class=cfg["instrument_class"],
    )
    try:
        fe.connect()
    except Exception:
        fe.close()
        raise
    return fe


def _health(fe: Any, since: Any = None) -> None:
    fe.idn  # noqa: B018 - a query to each lock-in proves both answer


SPEC = register_driver(
    DriverSpec(
        name="sr865-pair-frontend",
        role="frontend",
        part="outputs-off",
        keys={
            "driver": Key(str, required=True),
            "resource": Key(str, "", doc="VISA resource of the lock-in on channel 1 (the reference master)"),
            "resource2": Key(str, "", doc="VISA resource of the lock-in on channel 2 (locked to the master)"),
            "instrument_class": Key(str, "pymeasure.instruments.srs.SR860", doc="PyMeasure class of both"),
            "max_amplitude_v": Key(float, 2.0, 0.0, 2.8284, doc="largest sine-out amplitude asked", unit="V"),
            "timeout_s": Key(float, 2.0, 0.05, 60.0, doc="deadline of one query", unit="s"),
        },
        build=_build,
        serve="simulators.frontend.sr865_server:serve_station",
        health=_health,
        doc="two SR860-series lock-ins (PyMeasure) as the drive/pickoff front end",
    )
)
