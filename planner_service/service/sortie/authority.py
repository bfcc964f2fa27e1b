"""Who may command the vehicle's modes and arming. Pure.

The service commands modes and arming only inside a sortie the operator authorised: by the
configuration (``mavlink.start_mission``, for a stub or SITL) or by an operator command
over zenoh. It is a latch: any change it did not command or cannot explain (a pilot's mode
switch, a failsafe's, another ground station's, an autopilot restart, its own restart in
the air) ends that authority, and only the operator gives it back: the service stops
commanding and waits. A mode it does not know to expect (after a restart) explains no
change. A sortie that ended in a landing the service did not command does not get authority
from the configuration again: it never re-arms after a pilot's landing. The table of inputs
and outcomes is in docs/OPERATIONS.md ("Authority").
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

State = Literal["none", "operator", "revoked"]


@dataclass(frozen=True)
class Authority:
    state: State = "none"
    detail: str = "not given yet: the operator's start is awaited"
    """Why: who granted it, or what ended it."""
    expected_mode: str | None = None
    """The mode the service last commanded (or the mission's own return): another mode ends
    the authority. None: not known (nothing commanded yet, or after a restart): any change
    ends it."""

    @property
    def granted(self) -> bool:
        return self.state == "operator"

    @classmethod
    def by_configuration(cls) -> "Authority":
        return cls("operator", "given by the configuration (mavlink.start_mission = true)")

    @classmethod
    def by_operator(cls, reason: str = "") -> "Authority":
        return cls("operator", "given by the operator" + (f" ({reason})" if reason else ""))

    def revoke(self, why: str) -> "Authority":
        return Authority("revoked", f"revoked: {why}; the operator's start is awaited")

    def release(self, why: str) -> "Authority":
        """Handed back (the operator said hold): not a fault, but no more commands."""
        return Authority("none", why)

    def commanding(self, mode: str) -> "Authority":
        """The service commands ``mode`` now: that change is its own."""
        return replace(self, expected_mode=mode)

    def on_mode(self, mode: str, *, armed: bool, mission_return: bool, commanded: bool = False) -> "Authority":
        """The vehicle reports a change to ``mode``. A mode the link asked for (a step of the
        service's own command) and, in flight, the mission's own return (its last item,
        from a mode the service commanded) are the service's. Anything else ends the
        authority: a change while disarmed too (the ground crew's hand on the vehicle), and
        any change at all while the mode expected is unknown."""
        if not self.granted:
            return self
        if commanded:
            return replace(self, expected_mode=mode)
        if self.expected_mode is not None and mode == self.expected_mode:
            return self
        if mission_return and armed and self.expected_mode is not None:
            return replace(self, expected_mode=mode)
        was = self.expected_mode or "not known"
        return self.revoke(f"mode changed to {mode} (not commanded by the service; the mode expected: {was})")


def next_sortie(previous: Authority, *, start_mission: bool, commanded_landing: bool) -> Authority:
    """The authority a new sortie begins with: from the configuration only after a landing
    the service commanded (its mission's return, or its own return to launch) under its
    authority; otherwise the operator must grant it again."""
    if start_mission and commanded_landing and previous.state != "revoked":
        return Authority.by_configuration()
    if previous.state == "revoked":
        return Authority("none", f"not given yet: the operator's start is awaited (last sortie: {previous.detail})")
    return Authority()
