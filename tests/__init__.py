"""The test suites (a package, so that the shared helpers import as ``tests.support``)."""
