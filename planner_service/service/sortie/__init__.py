"""The sortie logic as a pure state machine (``machine.step``), with its parts: the state's
records (``life``, ``authority``, ``onboard``, ``holds``, ``schedule``, ``evidence``), the
mission held (``mission``), the watch over a hold (``hold``), and the records of what goes
in (``inputs``) and what comes out (``effects``)."""

from .authority import Authority
from .effects import Effect, PlanBasis
from .hold import HoldWatch, Sample
from .holds import Binding, Holds
from .inputs import Input, JournalView, VehicleSnapshot
from .life import Life
from .machine import Rules, Sortie, SortieLogic, new_sortie
from .mission import HeldMission, item_dict, item_from_dict
from .onboard import OnBoard
from .schedule import Schedule

__all__ = ["Authority", "Binding", "Effect", "HeldMission", "Holds", "HoldWatch", "Input", "item_dict",
           "item_from_dict", "JournalView", "Life", "new_sortie", "OnBoard", "PlanBasis", "Rules", "Sample",
           "Schedule", "Sortie", "SortieLogic", "VehicleSnapshot"]
