"""The fleet experiment (issue 26): N = 1..5 UAVs on the ``fleet`` preset, every planner of
the fleet registry against ``independent`` paired per seed, against ``joint`` where it is
registered and tractable, the message link swept for the planners that send messages, and
the paths of one sortie per planner. docs/EXPERIMENTS.md, "Fleet"."""

from .analysis import FleetResults, mean_se, verdict
from .design import (FULL_ITERATIONS, FULL_SEEDS, FULL_UAVS, QUICK_ITERATIONS, QUICK_SEEDS, FleetConfig,
                     fleet_jobs)
from .jobs import FleetJob, jain_index, run_fleet_job
from .run import run_fleet_experiment

__all__ = ["FULL_ITERATIONS", "FULL_SEEDS", "FULL_UAVS", "FleetConfig", "FleetJob", "FleetResults",
           "QUICK_ITERATIONS", "QUICK_SEEDS", "fleet_jobs", "jain_index", "mean_se", "run_fleet_experiment",
           "run_fleet_job", "verdict"]
