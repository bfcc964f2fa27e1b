"""The live fleet: one service per UAV, one user space over a zenoh router mesh, nothing
central (docs/OPERATIONS.md, "A fleet").

- ``presence``: this service's membership (its token, its signed announcement, the layer and
  clock rules at join), and the separation watch on the members' signed positions;
- ``roster``: who the members are (tokens with a fresh signed announcement), their layers
  and last positions; ``separation``: the pure judge of a pair's separation;
- ``airspace``: the one definition of the layers' gap and of a loss of separation;
- ``ledger``: the members' intentions and services (signed, bounded), read and written.
- ``settle``: when a claim of this member has settled (every claim made before it known).

The claim rule itself is ``planner_service.model.fleet.claims``, shared with the offline
``claims`` planner. The sortie logic hears the fleet as a typed input (``FleetHeard``) and
tells what it claims as an effect (``Intend``, ``sortie/fleet.py``); the service carries
them between the two and this package.
"""
