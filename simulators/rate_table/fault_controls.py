"""The fault controls every simulated table server offers, whatever its protocol."""

from __future__ import annotations

REPLY_FAULTS = ("short", "garbage", "drop")


class TableFaultControls:
    """Mixin for a table server with `world`, `mechanics` and a `link_faults` (kind, count, lock)."""

    def inject(self, kind: str, code: int | None = None) -> None:
        """Table fault: "estop", "fault" or "interlock"."""
        with self.world.lock:
            self.mechanics.inject(kind, code)

    def clear(self, kind: str) -> None:
        with self.world.lock:
            self.mechanics.clear(kind)

    #: the reply faults this server can make (the Modbus one adds "late")
    reply_faults: tuple[str, ...] = REPLY_FAULTS

    def corrupt_replies(self, kind: str, count: int = 1, *, late_s: float = 0.0) -> None:
        """Spoil the next `count` replies: "short" (truncated), "garbage" (mangled), "drop", or
        (where offered) "late": sent whole after late_s of wall time, beyond the client's timeout."""
        if kind not in self.reply_faults:
            raise ValueError(f"corrupt kind={kind!r}: expected one of {', '.join(self.reply_faults)}")
        with self.link_faults.lock:
            self.link_faults.kind, self.link_faults.count = kind, int(count)
            if late_s:
                self.link_faults.late_s = float(late_s)
