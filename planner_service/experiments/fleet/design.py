"""What the fleet experiment flies: its parameters (full and --quick forms) and its jobs.

Every planner in the fleet registry is flown (``fleet_algorithms``), so planners added to it
appear without edits here; ``joint`` only up to ``joint_max_uavs`` UAVs and where its search
fits (one search over K^N joint actions, at most ``MAX_JOINT_ACTIONS``: 40 points and 3 UAVs
are already 64,000); the message link swept only
for planners that take one (``fleet.takes_link``).
"""

from __future__ import annotations

from dataclasses import dataclass

from ...fleet import fleet_algorithms, joint_fits, takes_link
from ...model import Scenario
from .jobs import FleetJob

BASELINE = "independent"
"""Every coordinated planner is compared with this one, per seed."""
REFERENCE = "joint"
"""The reference where it is registered and tractable."""
FULL_UAVS = (1, 2, 3, 4, 5)
FULL_SEEDS = 30
QUICK_SEEDS = 3
FULL_ITERATIONS = 1000
QUICK_ITERATIONS = 100
LOSSES = (0.0, 0.2, 0.5)
LATES = (1, 2, 3)


@dataclass(frozen=True)
class FleetConfig:
    """The fleet experiment's parameters."""

    base: Scenario
    """The shared scenario (the ``fleet`` preset unless --preset/--set say otherwise)."""
    uavs: tuple[int, ...] = FULL_UAVS
    """Fleet sizes N flown by every planner."""
    seeds: tuple[int, ...] = tuple(range(FULL_SEEDS))
    """Worlds: every planner and N flies the same ones, so differences are paired per seed."""
    iterations: int = FULL_ITERATIONS
    """mcts iterations per decision of each UAV."""
    joint_max_uavs: int = 3
    """``joint`` is flown up to this N (its search grows as K^N). *decision*"""
    robustness_uavs: int = 3
    """The N at which the message link is swept (the issue's target is stated at N = 3)."""
    losses: tuple[float, ...] = LOSSES
    """Message loss rates swept, at lateness 0."""
    lates: tuple[int, ...] = LATES
    """Message lateness swept (sender's intervals), at loss 0."""
    quick: bool = False

    def __post_init__(self) -> None:
        if not self.uavs or min(self.uavs) < 1 or len(set(self.uavs)) != len(self.uavs):
            raise ValueError(f"uavs: distinct fleet sizes of at least 1 needed, got {list(self.uavs)}")
        if not self.seeds:
            raise ValueError("seeds: at least one seed needed")
        if self.iterations < 1:
            raise ValueError(f"iterations: at least 1 needed, got {self.iterations}")

    def planners(self) -> list[str]:
        """Every registered fleet planner, the baseline first."""
        return [BASELINE] + [a for a in fleet_algorithms() if a != BASELINE]

    def flies(self, algo: str, n: int) -> bool:
        """``joint`` only up to ``joint_max_uavs`` and where its search fits (K^N)."""
        return algo != REFERENCE or (n <= self.joint_max_uavs and joint_fits(self.base.num_hover_points, n))

    def link_planners(self) -> list[str]:
        """Planners whose messages' loss and lateness can be set."""
        return [a for a in self.planners() if takes_link(a)]

    def links(self) -> list[tuple[float, int]]:
        """(loss, late_intervals) swept: every loss at lateness 0, every lateness at loss 0."""
        return list(dict.fromkeys([(loss, 0) for loss in self.losses] + [(0.0, late) for late in self.lates]))

    def paths_uavs(self) -> int:
        """The N of the paths figure: 3 if flown (the issue's N), else the largest."""
        return 3 if 3 in self.uavs else max(self.uavs)


def fleet_jobs(cfg: FleetConfig) -> list[FleetJob]:
    """Every sortie of the experiment (duplicates removed by the runner)."""
    jobs = [FleetJob(cfg.base, n, a, cfg.iterations, seed)
            for n in cfg.uavs for a in cfg.planners() if cfg.flies(a, n) for seed in cfg.seeds]
    n = cfg.robustness_uavs
    jobs += [FleetJob(cfg.base, n, a, cfg.iterations, seed, link)
             for a in cfg.link_planners() if cfg.flies(a, n) for link in cfg.links() for seed in cfg.seeds]
    jobs += [FleetJob(cfg.base, cfg.paths_uavs(), a, cfg.iterations, cfg.seeds[0], record_paths=True)
             for a in cfg.planners() if cfg.flies(a, cfg.paths_uavs())]
    return jobs


__all__ = ["BASELINE", "FULL_ITERATIONS", "FULL_SEEDS", "FULL_UAVS", "FleetConfig", "LATES", "LOSSES",
           "QUICK_ITERATIONS", "QUICK_SEEDS", "REFERENCE", "fleet_jobs"]
