"""The fleet's airspace, one definition for the layer rule at join and the separation watch
in flight (docs/OPERATIONS.md, "A fleet"), pure.

Two armed vehicles have lost separation when they are closer than ``min_horizontal_m``
horizontally while closer than ``vertical_separation_m`` vertically (``separation_lost``).
Layers are kept ``vertical_separation_m`` plus ``altitude_margin_m`` apart (``layer_gap_m``):
a vehicle holds its layer only as well as its altitude estimate and its controller let it,
and two layers exactly the separation apart put every error on the wrong side of the rule
(issue 35: stacked ArduCopter SITL copters on 10 m layers were 9.98-10.04 m apart, and the
watch saw losses of separation that the layers were meant to rule out).

Decision: the margin defaults to 5 m. The SITL copters hold their layers within 0.05 m
(the issue's measurement); a real copter's barometric and GNSS altitude drift by a few
metres (a GNSS's vertical error is about 1.5 times its horizontal; baro drift with the
weather), so 5 m covers two vehicles each off by 2.5 m in opposite directions. It is a
parameter (``fleet.altitude_margin_m``): a fleet with better altimetry may lower it.
"""

from __future__ import annotations

VERTICAL_SEPARATION_M = 10.0
"""Two vehicles closer than this vertically are not separated by height
(``fleet.vertical_separation_m``)."""
ALTITUDE_MARGIN_M = 5.0
"""What two vehicles' altitude errors may add up to (``fleet.altitude_margin_m``)."""
MIN_HORIZONTAL_M = 20.0
"""Two vehicles not separated by height must stay this far apart horizontally
(``fleet.min_horizontal_m``)."""


def layer_gap_m(vertical_separation_m: float = VERTICAL_SEPARATION_M,
                altitude_margin_m: float = ALTITUDE_MARGIN_M) -> float:
    """The least distance between two members' layers: the vertical separation, plus the
    margin for the altitude errors of the two vehicles."""
    return vertical_separation_m + altitude_margin_m


def separation_lost(horizontal_m: float, vertical_m: float, min_horizontal_m: float = MIN_HORIZONTAL_M,
                    vertical_separation_m: float = VERTICAL_SEPARATION_M) -> bool:
    """Whether two vehicles this far apart have lost separation: neither far enough
    horizontally nor vertically."""
    return horizontal_m < min_horizontal_m and vertical_m < vertical_separation_m
