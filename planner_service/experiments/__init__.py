"""The paper's figures: experiment definitions, a process-pool runner, aggregation over
seeds (mean and 95 % t interval), the paper's claims checked, CSV/JSON writers and plots."""

from .claims import Check, Claim, near, positive, within
from .errors import ExperimentError
from .jobs import ALGOS, METRICS, STATIC, TRAINED, Job, Setting, replay_users, run_job
from .progress import Progress
from .registry import (EXPERIMENTS, FULL_EPISODES, FULL_SEEDS, QUICK_EPISODES, QUICK_SEEDS, Experiment,
                       RunConfig, experiment, three_d)
from .results import Results
from .run import run_experiments
from .runner import run_jobs
from .stats import Interval, mean_interval, t_critical_95
from .writers import write_csv, write_json

__all__ = [
    "ALGOS", "Check", "Claim", "EXPERIMENTS", "Experiment", "ExperimentError", "FULL_EPISODES", "FULL_SEEDS",
    "Interval", "Job", "METRICS", "Progress", "QUICK_EPISODES", "QUICK_SEEDS", "Results", "RunConfig", "STATIC",
    "Setting", "TRAINED", "experiment", "mean_interval", "near", "positive", "replay_users", "run_experiments",
    "run_job", "run_jobs", "t_critical_95", "three_d", "within", "write_csv", "write_json",
]
