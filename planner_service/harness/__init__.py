"""The harness that runs the service as it flies: child processes on loopback (the vehicle
stub, the service, the simulated users), the demo sortie, its report from the journal, and
the same world planned offline. Used by the demo, the benches and the tests; the service
itself imports none of it.

``demo`` is not re-exported: it imports the zenoh client, which the users of ``processes``
(most process tests) do not need."""

from .processes import Child, ChildError, free_port, start_vehicle_and_service, tied_to_parent
from .report import planned_requests, sortie_summary

__all__ = ["Child", "ChildError", "free_port", "planned_requests", "sortie_summary", "start_vehicle_and_service",
           "tied_to_parent"]
