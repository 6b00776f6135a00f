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

    def corrupt_replies(self, kind: str, count: int = 1) -> None:
        """Spoil the next `count` replies: "short" (truncated), "garbage" (mangled), "drop"."""
        if kind not in REPLY_FAULTS:
            raise ValueError(f"corrupt kind={kind!r}: expected 'short', 'garbage' or 'drop'")
        with self.link_faults.lock:
            self.link_faults.kind, self.link_faults.count = kind, int(count)
