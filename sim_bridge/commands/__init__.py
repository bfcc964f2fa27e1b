"""Subcommands of ``python -m sim_bridge``: each module has HELP, configure, run."""
