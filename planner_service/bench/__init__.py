"""Performance figures: decision latency of the planner, and against a plain reference."""

from .decisions import decision_states, time_decisions

__all__ = ["decision_states", "time_decisions"]
