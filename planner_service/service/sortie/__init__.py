"""The sortie logic as a pure state machine (``machine.step``), with its parts: the mission
held (``mission``), the watch over a hold (``hold``), who may command the vehicle
(``authority``), and the records of what goes in (``inputs``) and what comes out
(``effects``)."""

from .authority import Authority
from .effects import Effect, PlanBasis
from .hold import HoldWatch, Sample
from .inputs import Input, JournalView, VehicleSnapshot
from .machine import Binding, Rules, Sortie, SortieLogic, new_sortie
from .mission import HeldMission, item_dict, item_from_dict

__all__ = ["Authority", "Binding", "Effect", "HeldMission", "HoldWatch", "Input", "item_dict", "item_from_dict",
           "JournalView", "new_sortie", "PlanBasis", "Rules", "Sample", "Sortie", "SortieLogic", "VehicleSnapshot"]
