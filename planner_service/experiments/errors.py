"""The experiments' one exception type."""

from __future__ import annotations


class ExperimentError(Exception):
    """An experiment could not run: a sortie failed, or a name or option is wrong."""


__all__ = ["ExperimentError"]
