"""The protocol layer's exceptions: each carries the field or item that failed and why."""

from __future__ import annotations


class ProtocolError(ValueError):
    """A wire message was refused; ``field`` names the offending field (dotted path)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message


class SigningError(ValueError):
    """A signing key or timestamp file was refused; ``path`` names the file."""

    def __init__(self, path: str, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = path
        self.message = message


class MissionError(ValueError):
    """A mission (items, encoding or file) was refused; ``where`` names the item or field."""

    def __init__(self, where: str, message: str) -> None:
        super().__init__(f"{where}: {message}")
        self.where = where
        self.message = message
