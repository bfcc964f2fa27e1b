"""Who may command the vehicle's modes and arming. Pure.

The service commands modes and arming only inside a sortie the operator authorised: by an
operator command over zenoh, or by the configuration (``mavlink.start_mission``, for a stub
or SITL) for the first sortie of the process only, before anyone else acted. It is a latch:
any change it did not command or cannot explain (a pilot's mode switch, a failsafe's,
another ground station's, an arming or disarming, an autopilot restart, its own restart in
the air) ends that authority, and only the operator gives it back: the service stops
commanding and waits. A mode it does not know to expect (after a restart) explains no
change. Every later sortie waits for the operator's start: the service never arms again by
itself after a landing, its own or a pilot's. The table of inputs and outcomes is in
docs/OPERATIONS.md ("Authority").
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
    unused: bool = False
    """The configuration's, and nothing commanded under it yet: a process started between
    sorties gives it to the sortie it begins next."""

    @property
    def granted(self) -> bool:
        return self.state == "operator"

    @classmethod
    def by_configuration(cls) -> "Authority":
        return cls("operator", "given by the configuration (mavlink.start_mission = true)", unused=True)

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
        return replace(self, expected_mode=mode, unused=False)

    def on_mode(self, mode: str, *, armed: bool, mission_return: bool, commanded: bool = False,
                autopilots_own: bool = False) -> "Authority":
        """The vehicle reports a change to ``mode``. A mode the link asked for (a step of the
        service's own command), in flight the mission's own return (its last item, from a
        mode the service commanded), and a change the autopilot makes by itself at a known
        step of the service's sortie (``autopilots_own``: PX4's return to an earlier mode
        after the landing of the service's return disarmed it) are the service's. Anything else ends the
        authority: a change while disarmed too (the ground crew's hand on the vehicle), and
        any change at all while the mode expected is unknown."""
        if not self.granted:
            return self
        if commanded:
            return replace(self, expected_mode=mode, unused=False)
        if autopilots_own:
            return replace(self, expected_mode=mode)
        if self.expected_mode is not None and mode == self.expected_mode:
            return self
        if mission_return and armed and self.expected_mode is not None:
            return replace(self, expected_mode=mode)
        was = self.expected_mode or "not known"
        return self.revoke(f"mode changed to {mode} (not commanded by the service; the mode expected: {was})")


    def on_arming(self, armed: bool, *, commanded: bool, landing: bool) -> "Authority":
        """The vehicle reports it is now ``armed`` (or disarmed). An arming or disarming the
        link asked for is the service's, and so is a disarming at the end of a ``landing``
        of the service's (its mission's return, its own return to launch: the autopilot
        disarms on touching down). Anything else ends the authority: a pilot's or another
        station's arming, a disarming in the air (a motor kill) or on the ground (the
        ground crew's hand, the autopilot's own disarming of a start that did not take off:
        which of them cannot be told apart)."""
        if not self.granted or commanded or (not armed and landing):
            return self
        what = "armed" if armed else "disarmed"
        return self.revoke(f"the vehicle was {what} (not commanded by the service)")


def next_sortie(previous: Authority) -> Authority:
    """The authority a new sortie begins with: none, the operator's start is awaited, after
    a landing of the service's own too. The configuration's authority is for the first
    sortie the process flies: one it started in, over already, passes it on unused."""
    if previous.granted and previous.unused:
        return previous
    if previous.state == "revoked":
        return Authority("none", f"not given yet: the operator's start is awaited (last sortie: {previous.detail})")
    return Authority()
