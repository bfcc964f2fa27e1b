"""Helpers shared by the test suites, imported as ``tests.support.x`` (the checkout's root is
on the path: ``pythonpath`` in pyproject.toml; every folder of ``tests/`` is a package).

- ``sitl``: ArduCopter SITL, the reference autopilot, started and stopped for a test;
- ``stack``: the vehicle stub, the service and the simulated users as real processes on loopback;
- ``gcs``: a small pymavlink ground station (the GCS side of the mission protocol);
- ``sortie_checks``: every check of a whole sortie flown end to end, the journal against the
  vehicle's own log;
- ``truth``: what the vehicle really flew against what the service recorded;
- ``hostile_payloads``: hypothesis strategies of hostile zenoh payloads, and an oracle;
- ``mavlink_garbage``: garbage for a MAVLink link, reproducible from a seed;
- ``zenoh_tls``: the shipped zenoh TLS and access-control files, made usable in a test.
"""
