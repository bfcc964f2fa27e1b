"""The experiments by name: what each varies, which sorties it flies, which claims it checks.

Each experiment is a value (``Experiment``): its settings are built from the base scenario
(the preset with the command line's ``--set`` overrides), so the same definitions run on
the ``paper`` and the ``field`` presets. Plots live in ``plots.py``; this module holds the
numbers and the paper's claims about them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..model import Scenario
from .claims import Check, Claim, near, positive, within
from .errors import ExperimentError
from .jobs import ALGOS, STATIC, TRAINED, Job, Record, Setting
from .results import Results
from .timesaving import iterations_saved

FULL_EPISODES = (10, 30, 100, 300, 1000)
QUICK_EPISODES = (10, 30, 100)
FULL_SEEDS = 20
QUICK_SEEDS = 3

PAPER_MCTS = "mcts-paper"
OUR_MCTS = "mcts"
MCTS_ALGOS = (PAPER_MCTS, "ts-mcts", OUR_MCTS)
TIMING_REPEATS = 3
SHORT = {"average_reward": "reward", "throughput_tasks_per_interval": "throughput", "wall_s": "wall"}


@dataclass(frozen=True)
class RunConfig:
    """What the command line asked for."""

    base: Scenario
    episodes: tuple[int, ...] = FULL_EPISODES
    seeds: tuple[int, ...] = tuple(range(FULL_SEEDS))
    quick: bool = False


@dataclass(frozen=True)
class Experiment:
    """One figure of the paper (or of ours) and the claims it supports."""

    name: str
    title: str
    paper: str
    metric: str
    settings: Callable[[Scenario, bool], list[Setting]]
    claims: Callable[[Results], list[Claim]]
    plot: str
    """Name of the function in ``plots.py`` that draws it (imported on use: matplotlib is an
    optional dependency, and the command line must start without it)."""
    top_only: bool = False
    """Only the largest episodes count (the trajectory)."""
    paths: bool = False
    """Also record every algorithm's sortie of the first seed in every setting, with the users'
    positions, for a trajectory plot."""
    timing_repeats: int = 1
    """Fly each MCTS sortie this many times and keep the fastest (for wall-time claims)."""
    summary: Callable[[Results], dict] | None = None
    """Extra numbers for the JSON summary (``paired``), when the claims' intervals are not
    all a reader needs."""

    def draw(self, res: Results, out: Path) -> list[Path]:
        try:
            from . import plots
        except ImportError as err:
            raise ExperimentError(f"the figures need matplotlib ({err}): pip install -e '.[experiments]'") from None
        draw: Callable[[Experiment, Results, Path], list[Path]] = getattr(plots, self.plot)
        return draw(self, res, out)

    def episodes_for(self, cfg: RunConfig) -> tuple[int, ...]:
        return (max(cfg.episodes),) if self.top_only else tuple(cfg.episodes)

    def jobs(self, cfg: RunConfig) -> list[tuple[str, Job]]:
        """(setting label, job) pairs; ordered setting, episodes, seed, algorithm so that
        the sorties compared for wall time sit side by side in the runner's queue."""
        out: list[tuple[str, Job]] = []
        for setting in self.settings(cfg.base, cfg.quick):
            for n in self.episodes_for(cfg):
                for seed in cfg.seeds:
                    out += [(setting.label, Job(setting.scenario, a, n, seed,
                                                repeats=self.timing_repeats if a in MCTS_ALGOS else 1))
                            for a in TRAINED]
            for seed in cfg.seeds:
                out += [(setting.label, Job(setting.scenario, a, None, seed)) for a in STATIC]
            if self.paths:
                top = max(self.episodes_for(cfg))
                out += [(setting.label, Job(setting.scenario, a, None if a in STATIC else top, cfg.seeds[0], True))
                        for a in ALGOS]
        return out

    def results(self, cfg: RunConfig, cache: dict[Job, Record]) -> Results:
        res = Results(self.settings(cfg.base, cfg.quick), ALGOS, self.episodes_for(cfg), tuple(cfg.seeds))
        for label, job in self.jobs(cfg):
            if job not in cache:
                raise ExperimentError(f"{self.name}: {job.describe()} has not run")
            if job.record_paths:
                res.paths[(label, job.algo)] = cache[job]
            else:
                res.add(label, cache[job])
        return res


# --- settings ---------------------------------------------------------------------------

def speed_label(s: Scenario) -> str:
    return f"v={s.speed_mps:g} m/s"


def _as_given(base: Scenario, quick: bool) -> list[Setting]:
    return [Setting(speed_label(base), base)]


def _speeds(base: Scenario, quick: bool) -> list[Setting]:
    return [Setting(speed_label(s), s) for s in (base.replace(speed_mps=20.0), base.replace(speed_mps=10.0))]


def _phis(base: Scenario, quick: bool) -> list[Setting]:
    phis = (1.0, 5.0, 9.0) if quick else (1.0, 3.0, 5.0, 7.0, 9.0)
    return [Setting(f"phi={p:g}", base.replace(task_std=p)) for p in phis]


def _hover_counts(base: Scenario, quick: bool) -> list[Setting]:
    return [Setting(f"K={k}", base.replace(num_hover_points=k)) for k in (20, 30, 40)]


def _layouts(base: Scenario, quick: bool) -> list[Setting]:
    return [Setting(f"{name} layout", base.replace(hover_layout=name)) for name in ("original", "uniform")]


def three_d(base: Scenario) -> Scenario:
    """Appendix B's variant of ``base``: 27 points on planes at 25/50/75 m, users in 3-D,
    the base on the middle plane (``paper`` becomes exactly the ``paper-3d`` preset)."""
    if base.dimensions == 3:
        return base
    name = "paper-3d" if base.name == "paper" else f"{base.name}-3d"
    return base.replace(name=name, dimensions=3, num_hover_points=27, base_z_m=50.0)


def _three_d(base: Scenario, quick: bool) -> list[Setting]:
    return [Setting("3-D", three_d(base))]


def _task_models(base: Scenario, quick: bool) -> list[Setting]:
    return [Setting(f"{m} tasks", base.replace(task_model=m)) for m in ("redraw", "backlog")]


# --- claims -----------------------------------------------------------------------------

def _where(label: str, n: int | None) -> str:
    return label if n is None else f"{label}, n={n}"


def _beats(r: Results, metric: str, algo: str, others: tuple[str, ...], labels: list[str] | None = None,
           episodes: tuple[int, ...] | None = None) -> tuple[Check, ...]:
    """``algo`` above each of ``others`` at every setting and episodes count."""
    m = SHORT.get(metric, metric)
    checks = []
    for label in labels or r.labels:
        for n in episodes or r.episodes:
            for o in others:
                iv = r.paired(r.key(label, algo, n), r.key(label, o, n), metric)
                checks.append(positive(_where(label, n), f"{m}({algo}) - {m}({o})", iv))
    return tuple(checks)


def _best_claims(r: Results, metric: str, cid: str, source: str, text: str, others: tuple[str, ...],
                 episodes: tuple[int, ...] | None = None) -> list[Claim]:
    """The claim for the paper's MCTS, then the same comparison for ours (not the paper's claim,
    but what a reader would ask next), then both against greedy (which the paper omits)."""
    return [
        Claim(cid, source, text, _beats(r, metric, PAPER_MCTS, others, episodes=episodes)),
        Claim(cid + "-ours", "ours", f"{text} [with the project's mcts in place of Algorithm 1]",
              _beats(r, metric, OUR_MCTS, others, episodes=episodes)),
        Claim(cid + "-greedy", "context", "MCTS above greedy (the paper does not compare with greedy)",
              _beats(r, metric, PAPER_MCTS, ("greedy",), episodes=(r.top,))
              + _beats(r, metric, OUR_MCTS, ("greedy",), episodes=(r.top,))),
    ]


def _reward_claims(r: Results) -> list[Claim]:
    claims = _best_claims(r, "average_reward", "fig3-mcts-best", "Fig. 3",
                          "MCTS achieves the largest average reward among MCTS, DQN and QL", ("dqn", "ql"))
    claims.append(Claim("fig3-dqn-over-ql", "Fig. 3", "DQN above QL (the figures' ordering MCTS > DQN > QL)",
                        _beats(r, "average_reward", "dqn", ("ql",))))
    slow, fast = "v=10 m/s", "v=20 m/s"
    checks = []
    for algo in ALGOS:
        n = None if algo in STATIC else r.top
        iv = r.paired(r.key(slow, algo, n), r.key(fast, algo, n), "average_reward")
        checks.append(positive(_where(algo, n), "reward(10 m/s) - reward(20 m/s)", iv))
    claims.append(Claim("fig3-slower-better", "Fig. 3",
                        "A lower UAV speed gives a higher average reward for every algorithm", tuple(checks)))
    return claims


def _throughput_claims(r: Results) -> list[Claim]:
    metric = "throughput_tasks_per_interval"
    label = r.labels[0]
    claims = _best_claims(r, metric, "fig4-mcts-best", "Fig. 4",
                          "MCTS achieves the largest average throughput (above TS-MCTS, QL and DQN)",
                          ("ts-mcts", "dqn", "ql"))
    lo_n, hi_n = min(r.episodes), max(r.episodes)
    numbers = []
    for algo in (PAPER_MCTS, OUR_MCTS):
        for n, target in ((10, 8.35), (1000, 11.1)):
            if n in r.episodes:
                numbers.append(near(_where(label, n), f"throughput({algo}), paper {target}",
                                    r.point(label, algo, n, metric), target, 0.1 * target))
    claims.append(Claim("fig4-numbers", "Fig. 4 text",
                        "MCTS throughput about 8.35 tasks/interval at 10 episodes and 11.1 at 1000 "
                        "(checked within 10 %; the -ours row is our planner against the same numbers)",
                        tuple(numbers)))

    def growth(algo: str, seed: int) -> float:
        return r.values(label, algo, hi_n, metric)[seed] - r.values(label, algo, lo_n, metric)[seed]

    growth_checks = [positive(label, f"growth({PAPER_MCTS}) n={lo_n}->{hi_n}",
                              r.per_seed(lambda s: growth(PAPER_MCTS, s)))]
    for o in ("ts-mcts", "ql", "dqn"):
        growth_checks.append(positive(label, f"growth({PAPER_MCTS}) - growth({o})",
                                      r.per_seed(lambda s, o=o: growth(PAPER_MCTS, s) - growth(o, s))))
    claims.append(Claim("fig4-mcts-grows-most", "Fig. 4",
                        "MCTS throughput grows with the episodes, the most of all algorithms", tuple(growth_checks)))
    ts = list(_beats(r, metric, PAPER_MCTS, ("ts-mcts",)))

    def gap(n: int, seed: int) -> float:
        return r.values(label, PAPER_MCTS, n, metric)[seed] - r.values(label, "ts-mcts", n, metric)[seed]

    ts.append(positive(label, f"gap(n={lo_n}) - gap(n={hi_n}), gap = MCTS - TS-MCTS",
                       r.per_seed(lambda s: gap(lo_n, s) - gap(hi_n, s))))
    claims.append(Claim("fig4-ts-below", "Fig. 4",
                        "TS-MCTS throughput is below MCTS, and the gap closes as the episodes grow", tuple(ts)))
    return claims


def _robustness_claims(r: Results) -> list[Claim]:
    lo, hi = r.labels[0], r.labels[-1]
    checks = []
    for algo in ALGOS:
        n = None if algo in STATIC else r.top
        iv = r.paired(r.key(hi, algo, n), r.key(lo, algo, n), "average_reward")
        checks.append(positive(_where(algo, n), f"reward({hi}) - reward({lo})", iv))
    steps = []
    for a, b in zip(r.labels, r.labels[1:]):
        steps.append(positive(_where(PAPER_MCTS, r.top), f"reward({b}) - reward({a})",
                              r.paired(r.key(b, PAPER_MCTS, r.top), r.key(a, PAPER_MCTS, r.top), "average_reward")))
    return [
        Claim("fig5-reward-grows-with-phi", "Fig. 5",
              "The average reward increases with the task standard deviation phi (extremes, every algorithm)",
              tuple(checks)),
        Claim("fig5-steps", "Fig. 5", "... and at every step of phi (the paper's MCTS)", tuple(steps)),
        *_best_claims(r, "average_reward", "fig5-mcts-best", "Fig. 5 (implied)",
                      "MCTS has the largest reward at every phi", ("dqn", "ql"), episodes=(r.top,)),
    ]


def _hover_count_claims(r: Results) -> list[Claim]:
    metric = "throughput_tasks_per_interval"
    checks = []
    for algo in ALGOS:
        n = None if algo in STATIC else r.top
        for a, b in zip(r.labels, r.labels[1:]):
            checks.append(positive(_where(algo, n), f"throughput({b}) - throughput({a})",
                                   r.paired(r.key(b, algo, n), r.key(a, algo, n), metric)))
    return [
        *_best_claims(r, metric, "fig6-mcts-best", "Fig. 6",
                      "MCTS has the best throughput at every K", ("dqn", "ql"), episodes=(r.top,)),
        Claim("fig6-grows-with-k", "Fig. 6",
              "The throughput grows with K (20 -> 30 -> 40) for every algorithm", tuple(checks)),
    ]


def _layout_claims(r: Results) -> list[Claim]:
    metric = "throughput_tasks_per_interval"
    orig, uni = r.labels
    checks = []
    for algo in ALGOS:
        n = None if algo in STATIC else r.top
        tol = 0.05 * abs(r.point(orig, algo, n, metric).mean)
        checks.append(within(_where(algo, n), "throughput(uniform) - throughput(original)",
                             r.paired(r.key(uni, algo, n), r.key(orig, algo, n), metric), tol))
    return [
        Claim("appA-similar", "Appendix A",
              "Uniform and original layouts converge to similar throughput (difference within 5 %)", tuple(checks)),
        *_best_claims(r, metric, "appA-mcts-best", "Appendix A",
                      "MCTS has the largest throughput under both layouts", ("ts-mcts", "dqn", "ql"),
                      episodes=(r.top,)),
    ]


def _three_d_claims(r: Results) -> list[Claim]:
    return _best_claims(r, "average_reward", "appB-mcts-best", "Appendix B",
                        "MCTS obtains the largest average reward in 3-D (against DQN and QL)", ("dqn", "ql"))


def _timesaving_claims(r: Results) -> list[Claim]:
    label = r.labels[0]
    scenario = r.settings[0].scenario

    def saving(n: int, per_decision: bool) -> Callable[[int], float]:
        def fn(seed: int) -> float:
            ts = r.records[(label, "ts-mcts", n)][seed]
            paper = r.records[(label, PAPER_MCTS, n)][seed]
            if per_decision:
                return 1.0 - (ts["wall_s"] / ts["intervals"]) / (paper["wall_s"] / paper["intervals"])
            return 1.0 - ts["wall_s"] / paper["wall_s"]
        return fn

    total = [near(_where(label, n), "1 - wall(ts-mcts) / wall(mcts-paper), per sortie",
                  r.per_seed(saving(n, False)), 0.30, 0.10) for n in r.episodes]
    per = [near(_where(label, n), "the same per decision", r.per_seed(saving(n, True)), 0.30, 0.10)
           for n in r.episodes]
    iters = [near(_where(label, n), "1 - iterations(ts-mcts) / iterations(mcts-paper), per sortie",
                  r.per_seed(lambda s, n=n: iterations_saved(
                      scenario, n, int(r.records[(label, "ts-mcts", n)][s]["intervals"]))), 0.50, 0.10)
             for n in r.episodes]
    ours = [positive(_where(label, n), "1 - wall(mcts) / wall(mcts-paper), per sortie",
                     r.per_seed(lambda s, n=n: 1.0 - r.records[(label, OUR_MCTS, n)][s]["wall_s"]
                                / r.records[(label, PAPER_MCTS, n)][s]["wall_s"]))
            for n in r.episodes]
    return [
        Claim("ts-time", "Conclusions", "TS-MCTS saves about 30 % of the training (search) time (checked: 20-40 %)",
              tuple(total)),
        Claim("ts-time-per-decision", "Conclusions", "... per decision (sorties differ in length)", tuple(per)),
        Claim("ts-complexity", "Section III-C", "TS-MCTS reduces the complexity by 50 % (checked: iterations 40-60 %)",
              tuple(iters)),
        Claim("ts-ours-time", "context", "The project's mcts is faster than Algorithm 1 at equal n", tuple(ours)),
        Claim("ts-throughput", "Fig. 4", "TS-MCTS throughput is below MCTS",
              _beats(r, "throughput_tasks_per_interval", PAPER_MCTS, ("ts-mcts",))),
    ]


def _no_claims(r: Results) -> list[Claim]:
    return []


def _lookahead_gain(r: Results, label: str, n: int, metric: str, other: str = "greedy") -> dict[int, float]:
    """Per seed: ``mcts`` at n iterations minus ``other`` in one setting."""
    ours, theirs = r.values(label, OUR_MCTS, n, metric), r.values(label, other, None, metric)
    return {seed: ours[seed] - theirs[seed] for seed in ours if seed in theirs}


def _task_model_claims(r: Results) -> list[Claim]:
    redraw, backlog = r.labels
    claims = []
    for metric in ("average_reward", "throughput_tasks_per_interval"):
        m = SHORT.get(metric, metric)
        beats = []
        for label in (redraw, backlog):
            beats += [positive(_where(label, r.top), f"{m}(mcts) - {m}({o})",
                               r.paired(r.key(label, OUR_MCTS, r.top), r.key(label, o, None), metric))
                      for o in ("greedy", "random")]
        more = positive(_where("backlog - redraw", r.top), f"[{m}(mcts) - {m}(greedy)] backlog - the same, redraw",
                        r.per_seed(lambda s: _lookahead_gain(r, backlog, r.top, metric)[s]
                                   - _lookahead_gain(r, redraw, r.top, metric)[s]))
        claims += [
            Claim(f"tm-mcts-best-{m}", "ours", f"mcts above greedy and random in {m}, under either task model",
                  tuple(beats)),
            Claim(f"tm-lookahead-pays-more-{m}", "ours",
                  f"look-ahead pays more when tasks wait (backlog) than when they are redrawn: the {m} gain of "
                  "mcts over greedy is larger under backlog", (more,)),
        ]
    return claims


def paired_summary(r: Results) -> dict:
    """Medians, means and paired differences (mcts at the largest n, against greedy and
    random) per setting: the table of docs/PLANNER.md."""
    out: dict = {}
    for label in r.labels:
        rows: dict = {}
        for metric in ("average_reward", "throughput_tasks_per_interval"):
            m = SHORT.get(metric, metric)
            for algo in (OUR_MCTS, "greedy", "random"):
                vals = list(r.values(label, algo, None if algo in STATIC else r.top, metric).values())
                rows.setdefault(algo, {})[m] = {"median": float(np.median(vals)), **r.point(
                    label, algo, None if algo in STATIC else r.top, metric).as_dict()}
            for other in ("greedy", "random"):
                diff = list(_lookahead_gain(r, label, r.top, metric, other).values())
                iv = r.paired(r.key(label, OUR_MCTS, r.top), r.key(label, other, None), metric)
                rows.setdefault(f"mcts - {other}", {})[m] = {
                    "median": float(np.median(diff)), **iv.as_dict(),
                    "wins": int(sum(d > 0 for d in diff)), "losses": int(sum(d < 0 for d in diff))}
        out[label] = rows
    return out


EXPERIMENTS: dict[str, Experiment] = {e.name: e for e in (
    Experiment("reward-vs-episodes", "Average reward vs training episodes, 20 and 10 m/s", "Fig. 3",
               "average_reward", _speeds, _reward_claims, "plot_curves"),
    Experiment("throughput-vs-episodes", "Average throughput vs training episodes", "Fig. 4",
               "throughput_tasks_per_interval", _as_given, _throughput_claims, "plot_curves"),
    Experiment("robustness", "Average reward vs episodes for task standard deviations phi", "Fig. 5",
               "average_reward", _phis, _robustness_claims, "plot_by_algorithm"),
    Experiment("hover-count", "Average throughput for K = 20, 30, 40 hovering points", "Fig. 6",
               "throughput_tasks_per_interval", _hover_counts, _hover_count_claims, "plot_by_setting"),
    Experiment("hover-layout", "Average throughput with the original and a uniform layout", "Appendix A",
               "throughput_tasks_per_interval", _layouts, _layout_claims, "plot_layouts"),
    Experiment("trajectory", "The UAV's path and the served users", "Fig. 2",
               "throughput_tasks_per_interval", _as_given, _no_claims, "plot_trajectory",
               top_only=True, paths=True),
    Experiment("3d", "Average reward and trajectory in 3-D", "Appendix B",
               "average_reward", _three_d, _three_d_claims, "plot_three_d", paths=True),
    Experiment("timesaving", "TS-MCTS vs MCTS: search wall time and throughput", "Section III-C, Conclusions",
               "wall_s", _as_given, _timesaving_claims, "plot_timesaving", timing_repeats=TIMING_REPEATS),
    Experiment("task-model", "Tasks redrawn every interval (the paper) or waiting until served (backlog)", "ours",
               "average_reward", _task_models, _task_model_claims, "plot_curves", summary=paired_summary),
)}


def experiment(name: str) -> Experiment:
    try:
        return EXPERIMENTS[name]
    except KeyError:
        raise ExperimentError(f"unknown experiment {name!r}; choose from {sorted(EXPERIMENTS)} or 'all'") from None


__all__ = ["EXPERIMENTS", "Experiment", "FULL_EPISODES", "FULL_SEEDS", "QUICK_EPISODES", "QUICK_SEEDS",
           "RunConfig", "experiment", "paired_summary", "three_d"]
