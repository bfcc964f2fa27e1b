"""The model's one exception type."""

from __future__ import annotations


class ScenarioError(ValueError):
    """A scenario parameter or an environment input is invalid.

    ``field`` names what is wrong, so a command line or a zenoh reply can point at it.
    """

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field
