"""The simulated DAC/ADC front end: instrument model on the World, served as SCPI on loopback."""

from __future__ import annotations

from typing import Any

from .model import FORCE_SOURCE, FrontEndModel
from .server import FrontEndServer


def serve_frontend(
    world: Any,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    drive_gain: float = 50.0,
    pickoff_gain_v: float = 1.0,
    adc_noise_v: float = 1e-4,
    seed: int = 0,
) -> FrontEndServer:
    """Attach a front end to the world and serve it; the handle has resource_name, inject, stop."""
    model = FrontEndModel(drive_gain=drive_gain, pickoff_gain_v=pickoff_gain_v, adc_noise_v=adc_noise_v, seed=seed)
    return FrontEndServer(world, model, host=host, port=port).start()


def serve_station(world: Any, cfg: dict[str, Any]) -> tuple[FrontEndServer, dict[str, Any]]:
    """A simulated station's `scpi-frontend` (seeded by the world); (handle, its VISA resource)."""
    handle = serve_frontend(world, seed=world.seed)
    return handle, {"resource": handle.resource_name}


__all__ = ["FORCE_SOURCE", "FrontEndModel", "FrontEndServer", "serve_frontend", "serve_station"]
