"""The figures, with matplotlib (Agg: no display needed). Every figure shows every algorithm:
the paper's Algorithm 1 (``mcts-paper``), ``ts-mcts``, the project's ``mcts``, QL, DQN,
and greedy and random as flat lines (they have no episodes axis)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import matplotlib

matplotlib.use("Agg")  # before pyplot: the experiments run headless, in worker processes too
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..model import hover_points  # noqa: E402
from .jobs import ALGOS, STATIC  # noqa: E402
from .results import Results  # noqa: E402

if TYPE_CHECKING:
    from .registry import Experiment

DPI = 100
STYLE: dict[str, dict[str, Any]] = {
    "mcts-paper": {"color": "tab:red", "marker": "o", "label": "MCTS (paper, Alg. 1)"},
    "ts-mcts": {"color": "tab:orange", "marker": "s", "label": "TS-MCTS (paper)"},
    "mcts": {"color": "tab:blue", "marker": "D", "label": "mcts (ours)"},
    "ql": {"color": "tab:green", "marker": "^", "label": "QL"},
    "dqn": {"color": "tab:purple", "marker": "v", "label": "DQN"},
    "greedy": {"color": "black", "linestyle": "--", "label": "greedy"},
    "random": {"color": "gray", "linestyle": ":", "label": "random"},
}
YLABEL = {
    "average_reward": "average reward (11)",
    "throughput_tasks_per_interval": "throughput (tasks/interval)",
    "wall_s": "wall time per sortie (s)",
}


def _band(iv_lo: Sequence[float], iv_hi: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(iv_lo, dtype=float), np.asarray(iv_hi, dtype=float)


def draw_curves(ax: plt.Axes, r: Results, label: str, metric: str, algos: Sequence[str] = ALGOS) -> None:
    """One setting: a line with its 95 % band per trained algorithm against the episodes
    (log axis), a flat line with its band per static one."""
    xs = np.array(r.episodes, dtype=float)
    for algo in algos:
        st = STYLE[algo]
        if algo in STATIC:
            iv = r.point(label, algo, None, metric)
            ax.axhline(iv.mean, color=st["color"], linestyle=st["linestyle"], linewidth=1.2, label=st["label"])
            if np.isfinite(iv.lo):
                ax.axhspan(iv.lo, iv.hi, color=st["color"], alpha=0.08, linewidth=0)
            continue
        _, ivs = r.curve(label, algo, metric)
        lo, hi = _band([i.lo for i in ivs], [i.hi for i in ivs])
        ax.plot(xs, [i.mean for i in ivs], color=st["color"], marker=st["marker"], markersize=4,
                linewidth=1.4, label=st["label"])
        if np.isfinite(lo).all():
            ax.fill_between(xs, lo, hi, color=st["color"], alpha=0.15, linewidth=0)
    if len(xs) > 1:
        ax.set_xscale("log")
    ax.set_xlabel("training episodes (MCTS: iterations per decision)")
    ax.grid(True, alpha=0.3)


def _save(fig: plt.Figure, path: Path) -> Path:
    """Save at ``DPI`` as a 256-colour palette PNG: a third of the size of matplotlib's RGBA
    output, with no visible change for line plots, so the committed figures stay small."""
    from PIL import Image  # matplotlib's own dependency

    buf = io.BytesIO()
    fig.savefig(buf, dpi=DPI)
    plt.close(fig)
    buf.seek(0)
    with Image.open(buf) as im:
        im.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT,
                                   dither=Image.Dither.NONE).save(path, optimize=True)
    return path


def _title(exp: "Experiment", r: Results, scenario_name: str) -> str:
    return f"{exp.paper}: {exp.title} ({scenario_name}, {len(r.seeds)} seeds, 95% intervals)"


def plot_curves(exp: "Experiment", r: Results, out: Path) -> list[Path]:
    """One panel per setting, the metric against the episodes."""
    n = len(r.settings)
    fig, axes = plt.subplots(1, n, figsize=(5.2 * n, 4.2), sharey=True, squeeze=False)
    for ax, setting in zip(axes[0], r.settings):
        draw_curves(ax, r, setting.label, exp.metric)
        ax.set_title(setting.label)
        if exp.name == "throughput-vs-episodes":
            ax.plot([10, 1000], [8.35, 11.1], "kx", markersize=9, mew=2, label="paper's MCTS numbers")
    axes[0][0].set_ylabel(YLABEL[exp.metric])
    axes[0][-1].legend(fontsize=7, loc="best")
    fig.suptitle(_title(exp, r, r.settings[0].scenario.name), fontsize=9)
    fig.tight_layout()
    return [_save(fig, out / f"{exp.name}.png")]


def _summary_panel(ax: plt.Axes, r: Results, metric: str, xs: Sequence[float], xlabel: str) -> None:
    """The metric at the largest episodes count (static: their only value) across settings."""
    for algo in ALGOS:
        st = STYLE[algo]
        ivs = [r.point(s.label, algo, None if algo in STATIC else r.top, metric) for s in r.settings]
        lo, hi = _band([i.lo for i in ivs], [i.hi for i in ivs])
        ax.plot(xs, [i.mean for i in ivs], color=st["color"], marker=st.get("marker", "."),
                linestyle=st.get("linestyle", "-"), label=st["label"])
        if np.isfinite(lo).all():
            ax.fill_between(xs, lo, hi, color=st["color"], alpha=0.12, linewidth=0)
    ax.set_xlabel(xlabel)
    ax.set_title(f"at n={r.top} (static: as is)")
    ax.grid(True, alpha=0.3)


def _setting_values(r: Results, prefix: str) -> list[float]:
    return [float(s.label.split("=")[1].split()[0]) if s.label.startswith(prefix) else float(i)
            for i, s in enumerate(r.settings)]


def plot_by_algorithm(exp: "Experiment", r: Results, out: Path) -> list[Path]:
    """Robustness (Fig. 5): a panel per algorithm with a curve per setting (phi), and a panel
    of every algorithm's value at the largest n against phi."""
    cmap = plt.get_cmap("viridis")
    colors = [cmap(i / max(len(r.settings) - 1, 1)) for i in range(len(r.settings))]
    fig, axes = plt.subplots(2, 4, figsize=(16, 7.5), sharey=True)
    flat = axes.ravel()
    xs = np.array(r.episodes, dtype=float)
    for ax, algo in zip(flat, ALGOS):
        for color, setting in zip(colors, r.settings):
            if algo in STATIC:
                iv = r.point(setting.label, algo, None, exp.metric)
                ax.axhline(iv.mean, color=color, linestyle=STYLE[algo]["linestyle"], label=setting.label)
                continue
            _, ivs = r.curve(setting.label, algo, exp.metric)
            lo, hi = _band([i.lo for i in ivs], [i.hi for i in ivs])
            ax.plot(xs, [i.mean for i in ivs], color=color, marker="o", markersize=3, label=setting.label)
            if np.isfinite(lo).all():
                ax.fill_between(xs, lo, hi, color=color, alpha=0.12, linewidth=0)
        if len(xs) > 1:
            ax.set_xscale("log")
            ax.set_xlim(xs.min() / 1.3, xs.max() * 1.3)  # the flat panels too, which have no x data
        ax.set_title(STYLE[algo]["label"])
        ax.grid(True, alpha=0.3)
        ax.set_xlabel("episodes")
    flat[0].legend(fontsize=7)
    for row in axes:
        row[0].set_ylabel(YLABEL[exp.metric])
    _summary_panel(flat[len(ALGOS)], r, exp.metric, _setting_values(r, "phi"), "task standard deviation phi")
    flat[len(ALGOS)].legend(fontsize=6)
    fig.suptitle(_title(exp, r, r.settings[0].scenario.name), fontsize=9)
    fig.tight_layout()
    return [_save(fig, out / f"{exp.name}.png")]


def plot_by_setting(exp: "Experiment", r: Results, out: Path) -> list[Path]:
    """Hover count (Fig. 6): a panel per K, and every algorithm's value at the largest n against K."""
    n = len(r.settings)
    fig, axes = plt.subplots(1, n + 1, figsize=(4.4 * (n + 1), 4.2), sharey=True)
    for ax, setting in zip(axes, r.settings):
        draw_curves(ax, r, setting.label, exp.metric)
        ax.set_title(setting.label)
    _summary_panel(axes[-1], r, exp.metric, _setting_values(r, "K"), "hovering points K")
    axes[0].set_ylabel(YLABEL[exp.metric])
    axes[-1].legend(fontsize=7)
    fig.suptitle(_title(exp, r, r.settings[0].scenario.name), fontsize=9)
    fig.tight_layout()
    return [_save(fig, out / f"{exp.name}.png")]


def plot_layouts(exp: "Experiment", r: Results, out: Path) -> list[Path]:
    """Appendix A: a panel per layout, and a map of both layouts with the users' rows."""
    n = len(r.settings)
    fig, axes = plt.subplots(1, n + 1, figsize=(4.8 * (n + 1), 4.2))
    for ax, setting in zip(axes, r.settings):
        draw_curves(ax, r, setting.label, exp.metric)
        ax.set_title(setting.label)
        ax.set_ylabel(YLABEL[exp.metric])
    lows, highs = zip(*(ax.get_ylim() for ax in axes[:n]))
    for ax in axes[:n]:  # one scale, so the layouts compare by eye
        ax.set_ylim(min(lows), max(highs))
    ax = axes[-1]
    for setting, marker in zip(r.settings, ("^", "s")):
        hp = hover_points(setting.scenario)
        ax.scatter(hp[:, 0], hp[:, 1], marker=marker, s=30, facecolors="none",
                   edgecolors="tab:blue" if marker == "^" else "tab:orange", label=setting.label)
    _draw_user_rows(ax, r.settings[0].scenario)
    ax.set_aspect("equal")
    ax.set_title("hovering points")
    ax.legend(fontsize=7, loc="upper right")
    axes[0].legend(fontsize=7)
    fig.suptitle(_title(exp, r, r.settings[0].scenario.name), fontsize=9)
    fig.tight_layout()
    return [_save(fig, out / f"{exp.name}.png")]


def _draw_user_rows(ax: plt.Axes, scenario: Any) -> None:
    from ..model import user_rows

    users = user_rows(scenario.num_users, scenario.area_side_m)
    ax.scatter(users[:, 0], users[:, 1], marker="o", s=14, color="gray", label="users (start)")
    side = scenario.area_side_m
    ax.set_xlim(-10, side + 10)
    ax.set_ylim(-10, side + 10)


def _draw_path(ax: plt.Axes, scenario: Any, record: dict[str, Any], detailed: bool) -> None:
    """Users' tracks (thin), hovering points, the UAV's path from the base, served users (red stars)."""
    from ..model import base_position

    users = np.asarray(record["users_xyz"])  # (T + 1, I, 3)
    trace = record["trace"]
    hp = hover_points(scenario)
    ax.scatter(hp[:, 0], hp[:, 1], marker="^", s=22 if detailed else 10, color="tab:blue", alpha=0.5,
               label="hovering points")
    for i in range(users.shape[1]):
        ax.plot(users[:, i, 0], users[:, i, 1], color="gray", linewidth=0.8, alpha=0.8)
    ax.scatter(users[0, :, 0], users[0, :, 1], marker="o", s=16 if detailed else 8, color="gray",
               label="users (start; tracks)")
    if detailed:
        for i in range(users.shape[1]):
            ax.annotate(str(i), users[0, i, :2], textcoords="offset points", xytext=(3, -9), fontsize=7, color="gray")
    base = base_position(scenario)
    path = np.array([base] + [r["uav_xyz"] for r in trace])
    ax.plot(path[:, 0], path[:, 1], color="tab:purple", linewidth=1.5, label="UAV path")
    ax.scatter(path[:1, 0], path[:1, 1], marker="P", s=40, color="tab:purple")
    served = np.array([r["user_xyz"] for r in trace]) if trace else np.zeros((0, 3))
    ax.scatter(served[:, 0], served[:, 1], marker="*", s=120 if detailed else 50, color="red", zorder=5,
               label="served users")
    if detailed:
        # One label per hovering point, a line per visit, so that revisits do not overprint.
        visits: dict[int, list[str]] = {}
        for t, r in enumerate(trace):
            visits.setdefault(r["hover_point"], []).append(f"t={t + 1}: u{r['user']} ({r['tasks']})")
        for k, lines in visits.items():
            ax.annotate("\n".join(lines), hp[k, :2], textcoords="offset points", xytext=(4, 4), fontsize=7,
                        color="tab:purple", va="bottom", zorder=6)
    side = scenario.area_side_m
    ax.set_xlim(-15, side + 15)
    ax.set_ylim(-15, side + 15)
    ax.set_aspect("equal")


def _path_title(algo: str, record: dict[str, Any], episodes: int | None) -> str:
    n = "" if algo in STATIC else f", n={episodes}"
    return (f"{STYLE[algo]['label']}{n}: {record['throughput_tasks_per_interval']:.2f} tasks/int, "
            f"reward {record['average_reward']:.3f}")


def plot_trajectory(exp: "Experiment", r: Results, out: Path) -> list[Path]:
    """Fig. 2: the project's mcts in detail; a second figure with every other algorithm's path."""
    setting = r.settings[0]
    main = r.paths[(setting.label, "mcts")]
    fig, ax = plt.subplots(figsize=(7, 7))
    _draw_path(ax, setting.scenario, main, detailed=True)
    ax.set_title(f"{_path_title('mcts', main, r.top)}\n{setting.scenario.name}, {setting.label}, seed {r.seeds[0]}; "
                 "label: interval, user served (tasks)", fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    first = _save(fig, out / f"{exp.name}.png")
    others = [a for a in ALGOS if a != "mcts"]
    fig, axes = plt.subplots(2, 3, figsize=(13, 9))
    for ax, algo in zip(axes.ravel(), others):
        _draw_path(ax, setting.scenario, r.paths[(setting.label, algo)], detailed=False)
        ax.set_title(_path_title(algo, r.paths[(setting.label, algo)], r.top), fontsize=8)
    fig.suptitle(f"Fig. 2, the other algorithms ({setting.scenario.name}, {setting.label}, seed {r.seeds[0]})",
                 fontsize=9)
    fig.tight_layout()
    return [first, _save(fig, out / f"{exp.name}-others.png")]


def plot_three_d(exp: "Experiment", r: Results, out: Path) -> list[Path]:
    """Appendix B: the reward against the episodes, and the 3-D path of mcts with the users."""
    setting = r.settings[0]
    fig = plt.figure(figsize=(12, 5))
    ax = fig.add_subplot(1, 2, 1)
    draw_curves(ax, r, setting.label, exp.metric)
    ax.set_ylabel(YLABEL[exp.metric])
    ax.legend(fontsize=7)
    ax.set_title(f"{exp.paper}: average reward, 3-D ({len(r.seeds)} seeds)", fontsize=9)
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    record = r.paths[(setting.label, "mcts")]
    users = np.asarray(record["users_xyz"])
    hp = hover_points(setting.scenario)
    ax3.scatter(hp[:, 0], hp[:, 1], hp[:, 2], marker="^", s=12, color="tab:blue", alpha=0.5)
    for i in range(users.shape[1]):
        ax3.plot(users[:, i, 0], users[:, i, 1], users[:, i, 2], color="gray", linewidth=0.8)
    from ..model import base_position

    path = np.array([base_position(setting.scenario)] + [t["uav_xyz"] for t in record["trace"]])
    ax3.plot(path[:, 0], path[:, 1], path[:, 2], color="tab:pink", linewidth=2, label="UAV path (mcts)")
    served = np.array([t["user_xyz"] for t in record["trace"]])
    ax3.scatter(served[:, 0], served[:, 1], served[:, 2], marker="*", s=80, color="red", label="served users")
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z (m)")
    ax3.legend(fontsize=7)
    ax3.set_title(_path_title("mcts", record, r.top) + f", seed {r.seeds[0]}", fontsize=8)
    fig.tight_layout()
    return [_save(fig, out / f"{exp.name}.png")]


def plot_timesaving(exp: "Experiment", r: Results, out: Path) -> list[Path]:
    """Search wall time per sortie, TS-MCTS's saving over Algorithm 1 (paired by seed) with
    the schedule's iteration saving, and the throughput."""
    from .timesaving import iterations_saved

    setting = r.settings[0]
    label = setting.label
    xs = np.array(r.episodes, dtype=float)
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.6))
    draw_curves(axes[0], r, label, "wall_s")
    axes[0].set_yscale("log")
    axes[0].set_ylabel(YLABEL["wall_s"] + " (learners: training included)")
    axes[0].legend(fontsize=7)
    axes[0].set_title("wall time (same machine, same load)")
    ax = axes[1]
    # A ratio on a log axis: at small n a search takes milliseconds and fixed costs dominate,
    # so ratios far from 1 are common there and a percentage axis would hide the rest.
    for key, name, color in (("ts-mcts", "TS-MCTS / Alg. 1", "tab:orange"), ("mcts", "mcts (ours) / Alg. 1", "tab:blue")):
        ivs = [r.per_seed(lambda s, n=n: r.records[(label, key, n)][s]["wall_s"]
                          / r.records[(label, "mcts-paper", n)][s]["wall_s"]) for n in r.episodes]
        ax.plot(xs, [i.mean for i in ivs], color=color, marker="o", label=f"wall time {name}")
        lo, hi = _band([i.lo for i in ivs], [i.hi for i in ivs])
        if np.isfinite(lo).all():
            ax.fill_between(xs, np.maximum(lo, 1e-3), hi, color=color, alpha=0.15, linewidth=0)
    iters = [r.per_seed(lambda s, n=n: 1.0 - iterations_saved(
        setting.scenario, n, int(r.records[(label, "ts-mcts", n)][s]["intervals"]))) for n in r.episodes]
    ax.plot(xs, [i.mean for i in iters], color="black", linestyle="--", label="iterations TS-MCTS / Alg. 1 (schedule)")
    ax.axhline(0.7, color="gray", linestyle=":", label="paper: about 30 % less time")
    ax.axhline(1.0, color="black", linewidth=0.6)
    if len(xs) > 1:
        ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("iterations per decision n")
    ax.set_ylabel("ratio to Algorithm 1, per sortie")
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title("relative to Algorithm 1, paired by seed (mean of ratios)")
    draw_curves(axes[2], r, label, "throughput_tasks_per_interval")
    axes[2].set_ylabel(YLABEL["throughput_tasks_per_interval"])
    axes[2].set_title("throughput")
    fig.suptitle(_title(exp, r, setting.scenario.name), fontsize=9)
    fig.tight_layout()
    return [_save(fig, out / f"{exp.name}.png")]


__all__ = ["DPI", "STYLE", "draw_curves", "plot_by_algorithm", "plot_by_setting", "plot_curves", "plot_layouts",
           "plot_three_d", "plot_timesaving", "plot_trajectory"]
