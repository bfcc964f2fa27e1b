"""Helpers shared by the test suites (imported as ``support``; ``tests/`` is on the path
as the folder of the root conftest.py): ``support.sitl`` runs ArduCopter SITL."""
