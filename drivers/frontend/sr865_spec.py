"""The station entry of the two-SR865 front end (`driver = "sr865-pair-frontend"`): its keys, how
to build it, its health and safe-state part; bench.devices finds and imports this module."""

from __future__ import annotations

from typing import Any

from bench.devices import DriverSpec, Key, StationError, register_driver


def _build(cfg: dict[str, Any], clock: Any) -> Any:
    from .sr865_pair import Sr865Limits, Sr865PairFrontEnd, Sr865Setup

    if not cfg["resource2"]:
        raise StationError("[devices.frontend] resource2: the second lock-in's VISA resource is missing")
    fe = Sr865PairFrontEnd(
        cfg["resource"],
        cfg["resource2"],
        clock=clock,
        limits=Sr865Limits(max_amplitude_v=cfg["max_amplitude_v"]),
        setup=Sr865Setup(
            input_range_v=cfg["input_range_v"],
            sensitivity_v=cfg["sensitivity_v"],
            range_policy=cfg["range_policy"],
            ref_trigger=cfg["ref_trigger"],
            ref_impedance=cfg["ref_impedance"],
        ),
        timeout_s=cfg["timeout_s"],
        instrument_class=cfg["instrument_class"],
        visa_library=cfg["visa_library"],
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
            "input_range_v": Key(float, 1.0, 0.01, 1.0, doc="input range of both (IRNG: 1, 0.3, 0.1, 0.03, 0.01)",
                                 unit="V"),
            "sensitivity_v": Key(float, 1.0, 1e-9, 1.0, doc="full-scale sensitivity of both (SCAL, 1-2-5)", unit="V"),
            "range_policy": Key(str, "step-up", doc="on overload: one range up and the point again, or keep",
                                choices=("step-up", "fixed")),
            "ref_trigger": Key(str, "POS", doc="#2's reference trigger (RTRG): sine, TTL rising, TTL falling",
                               choices=("SIN", "POS", "NEG")),
            "ref_impedance": Key(str, "1MEG", doc="#2's reference input impedance (REFZ)", choices=("1MEG", "50OHMS")),
            "visa_library": Key(str, "", doc="pyvisa backend: '' (a vendor VISA if installed, else pyvisa-py), "
                                "'@py' (pyvisa-py), '@ivi'"),
            "simulated_visa": Key(str, "socket", doc="simulated stations: the lock-ins' VISA transport",
                                  choices=("socket", "vxi11")),
        },
        build=_build,
        serve="simulators.frontend.sr865_server:serve_station",
        health=_health,
        doc="two SR860-series lock-ins (PyMeasure) as the drive/pickoff front end",
    )
)
