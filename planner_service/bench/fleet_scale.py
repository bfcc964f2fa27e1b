"""``bench --fleet --scale``: fleets of N UAVs flown past one machine's loopback. Each UAV's
companion computer, each of the two ground routers and the ground station (the users, the
watcher) is a site in its own network namespace; the UAVs reach the ground over emulated
radio links (delay, jitter, loss: ``harness/sites.py``, ``sim_bridge wire``), and one UAV's
radio is cut mid-sortie and restored. Per N: the traffic (zenoh payloads on the fleet's keys
and the statuses, and the radio's own bytes both ways), how long the others' intentions take
to be heard, users served by two, holds of two at one point, the time to agree again after
the cut, decision time, CPU and memory per process, and flown against the offline fleet
planner; then a linear model of the traffic in N, fitted on the points and projected.
Figures, not pass/fail."""

from __future__ import annotations

import json
import re
import statistics
import tempfile
import time
from datetime import datetime
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..harness.demo import DemoError
from ..harness.fleet_demo import BASE_STEP_M, LAYER_M, run_fleet_demo
from ..harness.placement import SitePlacement
from ..harness.sites import Radio, Sites
from .fleet_flight import decision_ms

HEARD = re.compile(r"(\d+) intentions heard, p50 (\d+) ms, p99 (\d+) ms, max (\d+) ms")
LOG_TIME = re.compile(r"^(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3}) ")
BACKBONE = Radio(delay_ms=2.0)
"""The ground's own links (routers, the ground station) to the hub: a wired LAN."""
CUT_UAV = "uav1"
HOMES_SPAN_M = 480.0
"""The homes lie along the area's side (500 m), this far from the first to the last at most."""
MIN_HOME_STEP_M = 20.0
"""``fleet.min_horizontal_m``'s default: homes closer would put a climb out of separation."""


def heard(folder: Path) -> list[dict[str, float]]:
    """Each member's figures of the others' intentions heard (logged when it leaves)."""
    out = []
    for log in sorted(folder.glob("uav*/service.log")):
        for m in HEARD.finditer(log.read_text(errors="replace")):
            out.append({"count": int(m[1]), "p50_ms": float(m[2]), "p99_ms": float(m[3]), "max_ms": float(m[4])})
    return out


def rejoined_after(folder: Path, vehicle: str, restored_wall: float) -> float | None:
    """Seconds from the restore of ``vehicle``'s radio until every other member had its
    position again (``fleet: V's position known again`` or ``V joined`` after the restore):
    the fleet agreeing again on who flies where; None if one never did."""
    latest = 0.0
    for log in sorted(folder.glob("uav*/service.log")):
        if log.parent.name == vehicle:
            continue
        back = None
        for line in log.read_text(errors="replace").splitlines():
            if f"fleet: {vehicle}'s position known again" in line or f"fleet: {vehicle} joined" in line:
                m = LOG_TIME.match(line)
                at = datetime.strptime(m[1], "%Y-%m-%d %H:%M:%S,%f").timestamp() if m else 0.0
                if at >= restored_wall:
                    back = at - restored_wall
                    break
        if back is None:
            return None
        latest = max(latest, back)
    return latest


def radio_bytes(stats: dict[str, Any], vehicles: list[str]) -> dict[str, tuple[int, int]]:
    """(up, down) bytes each UAV's radio carried: up is its site toward the hub."""
    return {v: (stats[v]["a>b"]["bytes"], stats[v]["b>a"]["bytes"]) for v in vehicles if v in stats}


class CutOnce:
    """Cut ``vehicle``'s radio ``at_s`` after the users began, restore it ``for_s`` later."""

    def __init__(self, sites: Sites, vehicle: str, at_s: float, for_s: float) -> None:
        self.sites, self.vehicle, self.at_s, self.for_s = sites, vehicle, at_s, for_s
        self.cut_wall: float | None = None
        self.restored_wall: float | None = None
        self.first_stats: dict[str, Any] = {}
        self.last_stats: dict[str, Any] = {}
        """The wire's figures as the users began and as the fleet last flew."""

    def __call__(self, elapsed_s: float) -> None:
        stats = read_stats(self.sites)
        if not self.first_stats:
            self.first_stats = stats
        self.last_stats = stats
        if self.cut_wall is None and elapsed_s >= self.at_s:
            self.sites.cut(self.vehicle)
            self.cut_wall = time.time()
        elif self.cut_wall is not None and self.restored_wall is None and elapsed_s >= self.at_s + self.for_s:
            self.sites.restore(self.vehicle)
            self.restored_wall = time.time()


def radio_lateness(links: dict[str, Any]) -> dict[str, float]:
    """Of the packets the wire delivered on every link, the share it delivered late (more than
    ``sim_bridge.wire.LATE_MS`` after their delay: it was not given the CPU in time) and the
    latest: how far the radios were what was asked of them."""
    ways = [d for link in links.values() for k, d in link.items() if k in ("a>b", "b>a")]
    carried = sum(d["packets"] - d["dropped"] - d["cut"] - d["overflow"] for d in ways)
    late = sum(d.get("late", 0) for d in ways)
    return {"radio_late_share": late / carried if carried else 0.0,
            "radio_late_ms_max": max((d.get("late_ms_max", 0.0) for d in ways), default=0.0)}


def read_stats(sites: Sites) -> dict[str, Any]:
    """The wire's last figures (``{"at": monotonic s, "links": ...}``), or {} before its first."""
    try:
        return json.loads(sites.stats_path.read_text())
    except (OSError, ValueError):
        return {}


def fly_at_scale(folder: Path, uavs: int, radio: Radio, users: int, speedup: float, budget_ms: float, seed: int,
                 cut_at_s: float, cut_for_s: float, zenoh_mode: str, echo: Callable[[str], None]) -> dict[str, Any]:
    """One sortie of ``uavs`` UAVs over emulated links; the figures of one row."""
    sites = Sites(folder / "sites", seed=seed)
    sites.add("ground", BACKBONE)
    for i in range(2):
        sites.add(f"router{i + 1}", BACKBONE)
    vehicles = [f"uav{j + 1}" for j in range(uavs)]
    for vehicle in vehicles:
        sites.add(vehicle, radio, cable=True)
    # The layers 20 m apart from 40 m: past 5 UAVs above the legal 120 m (the first limit met,
    # docs/PERFORMANCE.md); the emulated airspace raises its ceiling to fit them all.
    ceiling_m = max(120.0, 40.0 + LAYER_M * (uavs - 1))
    # The homes 40 m apart east fit 13 along the area's side; more stand closer, never closer
    # than the separation's horizontal minimum (they climb through each other's layers there).
    home_step_m = min(BASE_STEP_M, float(int(HOMES_SPAN_M / max(1, uavs - 1))))
    if home_step_m < MIN_HOME_STEP_M:
        raise DemoError(f"{uavs} homes {home_step_m:g} m apart: closer than fleet.min_horizontal_m "
                        f"({MIN_HOME_STEP_M:g} m)")
    settings = {"safety.max_altitude_m": f"{ceiling_m:g}",
                # sites this process made, reachable by nothing else on the machine
                "fleet.insecure": "true"}
    with sites:
        cut = CutOnce(sites, CUT_UAV, cut_at_s, cut_for_s)
        sites.enter("ground")
        try:
            summary = run_fleet_demo(folder, uavs=uavs, users=users, speedup=speedup, budget_ms=budget_ms, seed=seed,
                                     timeout_s=900.0, echo=echo, placement=SitePlacement(sites), settings=settings,
                                     during=cut, zenoh_mode=zenoh_mode, home_step_m=home_step_m)
        finally:
            sites.leave()
    return row(folder, vehicles, summary, cut, ceiling_m)


def row(folder: Path, vehicles: list[str], summary: dict[str, Any], cut: CutOnce, ceiling_m: float) -> dict[str, Any]:
    first, last = cut.first_stats, cut.last_stats
    span_s = max(1e-9, last.get("at", 0.0) - first.get("at", 0.0))
    before, after = radio_bytes(first.get("links", {}), vehicles), radio_bytes(last.get("links", {}), vehicles)
    up = [(after[v][0] - before.get(v, (0, 0))[0]) / span_s for v in after]
    down = [(after[v][1] - before.get(v, (0, 0))[1]) / span_s for v in after]
    traffic = summary["traffic_bytes_per_s"].values()
    members = heard(folder)
    processes = summary["processes"]
    services = [p for name, p in processes.items() if name.startswith("service ")]
    every_ms = decision_ms(folder)
    return {
        "uavs": len(vehicles), "ceiling_m": ceiling_m, "home_step_m": summary["base_step_m"],
        "fleet_keys_bytes_per_s": statistics.median(t["fleet_keys"] for t in traffic),
        "status_bytes_per_s": statistics.median(t["status"] for t in traffic),
        "fleet_keys_by_kind_bytes_per_s": summary["fleet_keys_by_kind_bytes_per_s"],
        "radio_up_bytes_per_s": statistics.median(up) if up else None,
        "radio_down_bytes_per_s": statistics.median(down) if down else None,
        **radio_lateness(last.get("links", {})),
        "heard_p50_ms": statistics.median(m["p50_ms"] for m in members) if members else None,
        "heard_p99_ms": max(m["p99_ms"] for m in members) if members else None,
        "users_served_by_two": len(summary["fleet"]["users_served_by_two_uavs"]),
        "users_served_at_once": summary["fleet"]["users_served_at_once"],
        "stacked_holds": summary["fleet"]["stacked_holds"],
        "holds_of_two": summary["fleet"]["holds_of_two"],
        "agreed_after_s": (rejoined_after(folder, CUT_UAV, cut.restored_wall)
                           if cut.restored_wall is not None else None),
        "decision_ms_median": statistics.median(every_ms) if every_ms else None,
        "service_cpu_percent": statistics.median(p["cpu_percent"] or 0.0 for p in services),
        "service_rss_mb": statistics.median(p["peak_rss_mb"] or 0.0 for p in services),
        "router_cpu_percent": max(p["cpu_percent"] or 0.0 for n, p in processes.items() if n.startswith("router")),
        "flown": summary["fleet"]["throughput_tasks_per_interval"],
        "offline": summary["offline"]["throughput_tasks_per_interval"],
        "flown_to_offline": summary["flown_to_offline"],
        "fairness_violations": summary["fleet"]["fairness_violations"],
        "wall_s": summary["wall_s"],
    }


def fit_line(points: list[tuple[float, float]]) -> tuple[float, float]:
    """Least squares ``y = a + b * x`` (numpy's ``polyfit``): (a, b); with one x only, the
    mean of its ys and no slope."""
    xs, ys = np.array([x for x, _ in points], dtype=float), np.array([y for _, y in points], dtype=float)
    if len(set(xs.tolist())) < 2:
        return (float(ys.mean()) if len(ys) else 0.0), 0.0
    b, a = np.polyfit(xs, ys, 1)
    return float(a), float(b)


def traffic_model(rows: list[dict[str, Any]], project_to: list[int]) -> dict[str, Any]:
    """Per UAV, bytes/s = a + b N for what it sends (fleet keys, radio up) and what it
    receives (radio down), fitted on the measured rows; the fit's worst relative error on
    them, and the projection."""
    out: dict[str, Any] = {}
    for name in ("fleet_keys_bytes_per_s", "radio_up_bytes_per_s", "radio_down_bytes_per_s"):
        points = [(float(r["uavs"]), float(r[name])) for r in rows if r.get(name) is not None]
        if not points:
            continue
        a, b = fit_line(points)
        worst = max(abs(a + b * x - y) / y for x, y in points if y) if points else 0.0
        out[name] = {"a": a, "b": b, "worst_fit_error": worst,
                     "projected": {n: a + b * n for n in project_to}}
    return out


def run_fleet_scale(uav_counts: list[int], radio: Radio, users_per_uav: int, speedup: float, budget_ms: float,
                    seed: int, cut_at_s: float, cut_for_s: float, progress: Callable[[str], None],
                    keep: Path | None = None, zenoh_mode: str = "client") -> dict[str, Any]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="fleet-scale-") as tmp:
        base = keep or Path(tmp)
        for n in uav_counts:
            progress(f"N={n}: {n} sites over {radio.delay_ms:g}+-{radio.jitter_ms:g} ms, loss {radio.loss:g} ...")
            r = fly_at_scale(base / f"n{n}", n, radio, users_per_uav * n, speedup, budget_ms, seed, cut_at_s,
                             cut_for_s, zenoh_mode, echo=lambda _: None)
            rows.append(r)
            progress(f"  N={n}: flown/offline {r['flown_to_offline'] or 0:.2f}, fleet keys "
                     f"{r['fleet_keys_bytes_per_s']:.0f} B/s, radio down {r['radio_down_bytes_per_s'] or 0:.0f} B/s "
                     f"per UAV, served by two {r['users_served_by_two']} (at once {len(r['users_served_at_once'])}), "
                     f"stacked {len(r['stacked_holds'])} (both hovering {len(r['holds_of_two'])})")
    return {"radio": vars(radio), "zenoh_mode": zenoh_mode, "users_per_uav": users_per_uav, "speedup": speedup,
            "budget_ms": budget_ms, "seed": seed, "cut": {"vehicle": CUT_UAV, "at_s": cut_at_s, "for_s": cut_for_s}, "rows": rows,
            "model": traffic_model(rows, [20, 50, 100])}


def format_fleet_scale(results: dict[str, Any]) -> str:
    r0 = results["radio"]
    lines = [f"fleets over emulated radios ({r0['delay_ms']:g}+-{r0['jitter_ms']:g} ms each way, loss {r0['loss']:g}; "
             f"services zenoh {results['zenoh_mode']}s; "
             f"stubs x{results['speedup']:g}, {results['users_per_uav']} users per UAV, {results['budget_ms']:g} ms "
             f"per decision; {results['cut']['vehicle']}'s radio cut at {results['cut']['at_s']:g} s for "
             f"{results['cut']['for_s']:g} s)",
             f"{'N':>3} {'flown/off':>9} {'keys B/s':>8} {'status':>7} {'up B/s':>7} {'down B/s':>8} "
             f"{'heard p50':>9} {'p99 ms':>7} {'by two':>6} {'at once':>7} {'stacked':>7} {'hovering':>8} {'agreed s':>8} {'dec ms':>6} "
             f"{'svc CPU%':>8} {'svc MB':>6} {'rtr CPU%':>8}"]

    def f(value: Any, spec: str) -> str:
        return "-" if value is None else format(value, spec)

    for r in results["rows"]:
        lines.append(f"{r['uavs']:>3} {f(r['flown_to_offline'], '.2f'):>9} {r['fleet_keys_bytes_per_s']:>8.0f} "
                     f"{r['status_bytes_per_s']:>7.0f} {f(r['radio_up_bytes_per_s'], '.0f'):>7} "
                     f"{f(r['radio_down_bytes_per_s'], '.0f'):>8} {f(r['heard_p50_ms'], '.0f'):>9} "
                     f"{f(r['heard_p99_ms'], '.0f'):>7} {r['users_served_by_two']:>6} "
                     f"{len(r['users_served_at_once']):>7} {len(r['stacked_holds']):>7} {len(r['holds_of_two']):>8} "
                     f"{f(r['agreed_after_s'], '.1f'):>8} {f(r['decision_ms_median'], '.0f'):>6} "
                     f"{r['service_cpu_percent']:>8.1f} {r['service_rss_mb']:>6.0f} {r['router_cpu_percent']:>8.1f}")
    for r in results["rows"]:
        kinds = ", ".join(f"{k} {v:.0f}" for k, v in r["fleet_keys_by_kind_bytes_per_s"].items())
        lines.append(f"N={r['uavs']}: radio packets delivered late {100 * r.get('radio_late_share', 0.0):.2f} % "
                     f"(latest {r.get('radio_late_ms_max', 0.0):.0f} ms); the fleet's keys per member, B/s: {kinds}; "
                     f"served at once: "
                     f"{', '.join(r['users_served_at_once']) or 'none'}; stacked: "
                     f"{', '.join(r['stacked_holds']) or 'none'}; holds of two (both hovering): "
                     f"{', '.join(r['holds_of_two']) or 'none'}")
    lines.append("traffic per UAV, bytes/s = a + b N (fitted on the rows above; worst fit error; projected):")
    for name, m in results["model"].items():
        projected = ", ".join(f"N={n}: {v:.0f}" for n, v in m["projected"].items())
        lines.append(f"  {name}: a={m['a']:.0f} b={m['b']:.1f} (worst error {100 * m['worst_fit_error']:.0f} %); "
                     f"{projected}")
    return "\n".join(lines)
