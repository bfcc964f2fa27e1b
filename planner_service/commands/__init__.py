"""Subcommands of ``python -m planner_service``: each module has HELP, configure, run."""
