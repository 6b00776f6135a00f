"""The safe state, in the engine's order: cut the drive, bring the table to rest within its
acceleration limit, turn outputs off; each confirmed by the device's own read-back."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from bench.devices import SAFE_PARTS

#: roles in the order the safe state visits them; a role not listed goes last
SAFE_ORDER: tuple[str, ...] = ("fpga", "table", "frontend")


@dataclass
class SafeStateReport:
    """confirmed is True only when every device confirmed by read-back."""

    confirmed: bool
    devices: dict[str, bool] = field(default_factory=dict)
    errors: dict[str, str] = field(default_factory=dict)
    order: list[str] = field(default_factory=list)


def ordered_roles(roles: Iterable[str]) -> list[str]:
    roles = list(roles)
    rank = {r: i for i, r in enumerate(SAFE_ORDER)}
    return sorted(roles, key=lambda r: (rank.get(r, len(SAFE_ORDER)), roles.index(r)))


def by_part(parts: dict[str, str]) -> list[tuple[str, list[str]]]:
    """Roles (role -> part) grouped into SAFE_PARTS order, each part's roles in the given order."""
    unknown = sorted({p for p in parts.values() if p not in SAFE_PARTS})
    if unknown:
        raise ValueError(f"safe-state part(s) {unknown} not one of {SAFE_PARTS}")
    return [(part, [r for r, p in parts.items() if p == part]) for part in SAFE_PARTS]


def bring_to_safe_state(devices: dict[str, Any]) -> SafeStateReport:
    """Call `safe_state()` on every device in SAFE_ORDER, whatever the earlier ones answered: a
    table must come to rest even when the drive cut could not be confirmed."""
    report = SafeStateReport(confirmed=True)
    for role in ordered_roles(devices):
        dev = devices[role]
        report.order.append(role)
        fn = getattr(dev, "safe_state", None)
        if fn is None:
            continue
        try:
            ok = bool(fn())
        except Exception as exc:  # noqa: BLE001 - the next device must still be made safe
            ok = False
            report.errors[role] = f"{type(exc).__name__}: {exc}"
        report.devices[role] = ok
        report.confirmed = report.confirmed and ok
    return report
