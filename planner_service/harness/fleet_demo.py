"""The demo of a fleet (``demo --uavs N``): two meshed zenoh routers, N vehicle stubs each
with its own service (its journal, its layer, its home), and the simulated users submitting
once to the fleet, all real processes on loopback; nothing central. Then a summary per UAV
and for the fleet, the fleet flown against the offline fleet planner on the same scenario and
seed, the coordination traffic each UAV sent, and one figure with every path."""

from __future__ import annotations

import json
import shutil
import threading
import time
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any, Callable

import zenoh

from protocol import Event, FleetKeys, GeoOrigin, Keys, Status, decode, encode, local_to_global
from protocol.fleet_signing import make_vehicle_key
from protocol.zenoh_config import session_config

from ..fleet.sortie import run_fleet_sortie
from ..model import Scenario
from ..model.fairness import fairness_violations
from ..model.fleet import Fleet, uav_scenarios
from ..policy import PolicySpec
from ..service.config import build_config, to_toml
from ..service.errors import ServiceError
from .placement import Loopback, Placement
from ..service.journal import Journal
from .demo import DemoError, area_axes
from .live_map import LiveMap
from .processes import Child, cpu_seconds, peak_rss_mb
from .doubles import HOVER_MPS, served_at_once, stacked_holds
from .report import sortie_summary

LAYER_M = 20.0
"""The layers' spacing: at least the services' default layer gap (``fleet.vertical_separation_m``
10 m + ``fleet.altitude_margin_m`` 5 m), in round metres, as docs/OPERATIONS.md's examples."""
BASE_STEP_M = 40.0
"""UAV j's home lies j times this east of the origin: twice ``fleet.min_horizontal_m``,
since the UAVs climb through each other's layers above their homes."""
FENCE_MARGIN_M = 100.0
"""The stub's own default geofence margin around the area (``vehicle --fence-margin``)."""
OFFLINE_ALGO = "claims"
"""The offline fleet planner the flight is held against: the rule the services fly (a user
is the UAV's that claims it first, docs/PLANNER.md)."""


def fleet_of(uavs: int, home_step_m: float = BASE_STEP_M) -> Fleet:
    return Fleet(uavs=uavs, layer_m=LAYER_M, base_step_m=home_step_m)


def offline_fleet(base: Scenario, users: int, fleet: Fleet, seed: int, budget_ms: float) -> dict[str, Any]:
    """The fleet's sortie planned offline by ``OFFLINE_ALGO`` in the flown world (the users'
    tasks arriving in time, as ``sim_bridge users`` draws them): ``run_fleet_sortie``'s
    ``fleet`` summary."""
    world = base.replace(num_users=users, task_model="backlog")
    return run_fleet_sortie(world, fleet, OFFLINE_ALGO, seed, PolicySpec(iterations=None, budget_ms=budget_ms))["fleet"]


def lowest_layer_m(default: Scenario, uavs: int, max_altitude_m: float) -> float:
    """UAV 0's layer: the services' default altitude, lowered so that the highest of ``uavs``
    layers stays within ``safety.max_altitude_m`` (120 m: the usual legal ceiling)."""
    return min(default.altitude_m, max_altitude_m - (uavs - 1) * LAYER_M)


def scenario_settings(base: Scenario, own: Scenario) -> dict[str, str]:
    """The ``scenario.*`` settings that make a service fly ``own`` (a UAV's of ``base``)."""
    a, b = base.as_dict(), own.as_dict()
    out = {}
    for name, value in b.items():
        if value != a.get(name):
            out[f"scenario.{name}"] = ",".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)
    return out


class Watch:
    """Every vehicle's statuses and events, and the bytes each member sent on the fleet's
    keys, as a client of the routers sees them."""

    def __init__(self, session: Any, prefix: str) -> None:
        self.lock = threading.Lock()
        self.statuses: dict[str, list[Status]] = defaultdict(list)
        self.events: list[tuple[str, Event]] = []
        self.fleet_bytes: Counter[str] = Counter()
        self.status_bytes: Counter[str] = Counter()
        self.fleet_kinds: Counter[str] = Counter()
        """Bytes on the fleet's keys by kind (positions, uavs, intentions, served), all members."""
        self.fleet = FleetKeys(prefix)
        self._calm_since: float | None = None
        self._subs = [session.declare_subscriber(self.fleet.statuses, self._status),
                      session.declare_subscriber(f"{prefix}/*/events", self._event),
                      session.declare_subscriber(f"{prefix}/fleet/**", self._fleet)]

    def _status(self, sample: Any) -> None:
        vehicle = self.fleet.status_vehicle(str(sample.key_expr))
        if vehicle is None:
            return
        data = sample.payload.to_bytes()
        with self.lock:
            self.status_bytes[vehicle] += len(data)
            self.statuses[vehicle].append(decode(data, Status))

    def _event(self, sample: Any) -> None:
        vehicle = str(sample.key_expr).split("/")[1]
        with self.lock:
            self.events.append((vehicle, decode(sample.payload.to_bytes(), Event)))

    def _fleet(self, sample: Any) -> None:
        # {prefix}/fleet/{kind}/{vehicle}[/@adv/...]: announcements, intentions, services
        parts = str(sample.key_expr).split("/")
        if len(parts) >= 4:
            size = len(sample.payload.to_bytes())
            with self.lock:
                self.fleet_bytes[parts[3]] += size
                self.fleet_kinds[parts[2]] += size

    def over(self, vehicles: list[str], calm_s: float = 3.0) -> bool:
        """The sortie is over: a UAV has landed and none has been armed for ``calm_s`` (a
        UAV whose share was empty never took off)."""
        with self.lock:
            last = [self.statuses[v][-1] if self.statuses[v] else None for v in vehicles]
        armed = any(s is None or s.armed for s in last)
        if armed or not self.landed():
            self._calm_since = None
            return False
        self._calm_since = self._calm_since or time.monotonic()
        return time.monotonic() - self._calm_since >= calm_s

    def landed(self) -> set[str]:
        with self.lock:
            return {v for v, e in self.events if e.event == "landed"}

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def enrol_fleet(folder: Path, vehicles: list[str]) -> Path:
    """Every vehicle's fleet key and the fleet's roster in ``folder`` (made afresh: the demo's
    own, as ``python -m planner_service fleet-key`` makes them); returns the roster's path."""
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(mode=0o700, parents=True)
    roster = folder / "roster"
    for vehicle in vehicles:
        make_vehicle_key(folder / f"{vehicle}.key", roster, vehicle)
    return roster


def run_fleet_demo(out: Path, *, uavs: int = 3, users: int = 12, speedup: float = 25.0, budget_ms: float = 150.0,
                   seed: int = 1, timeout_s: float = 300.0, offline: bool = True,
                   echo: Callable[[str], None] = print, web: bool = False, placement: Placement | None = None,
                   settings: dict[str, str] | None = None,
                   during: Callable[[float], None] | None = None, zenoh_mode: str = "peer",
                   home_step_m: float = BASE_STEP_M) -> dict[str, Any]:
    """Fly one sortie with ``uavs`` UAVs; returns the summary (also ``out/summary.json``). The
    live map's address is printed once the services are up; with ``web`` the page (and the
    fleet) stay until Ctrl-C after the landings. ``placement``: where each process runs
    (default: all on loopback); ``settings``: more of the services' settings (``safety.*``:
    also the layers' ceiling); ``during``: called while the fleet flies with the seconds since
    the users began (a bench cuts a link there); ``zenoh_mode``: the services' (``peer``:
    each listens and links to every other it hears of; ``client``: each to one router); ``home_step_m``: the homes' spacing east (more UAVs than fit
    the area's side at ``BASE_STEP_M`` stand closer, never under ``fleet.min_horizontal_m``)."""
    out.mkdir(parents=True, exist_ok=True)
    placement = placement or Loopback()
    settings = settings or {}
    defaults = _config(settings)
    default = defaults.scenario()
    lowest = lowest_layer_m(default, uavs, defaults.safety.max_altitude_m)
    if lowest < defaults.safety.min_flight_altitude_m:
        raise DemoError(f"{uavs} layers {LAYER_M:g} m apart do not fit between safety.min_flight_altitude_m "
                        f"and safety.max_altitude_m ({defaults.safety.min_flight_altitude_m:g}, "
                        f"{defaults.safety.max_altitude_m:g} m)")
    base = default.replace(altitude_m=lowest, base_z_m=lowest)
    fleet = fleet_of(uavs, home_step_m)
    scenarios = uav_scenarios(base, fleet)
    origin = defaults.origin_point()
    routers = [placement.router_endpoint(i) for i in range(2)]
    children: list[Child] = []
    watched: dict[str, Child] = {}
    """The routers' and the UAVs' processes, whose CPU and memory the summary reports."""
    start = time.monotonic()
    echo(f"demo: {uavs} UAVs (vehicle stubs x{speedup:g}), {uavs} services, 2 routers, {users} users "
         f"submitting to the fleet; logs in {out}")
    session = None
    live = LiveMap(routers, Keys().prefix, echo=echo)
    try:
        for i, endpoint in enumerate(routers):
            args = ["router", "--listen", endpoint, *(["--connect", routers[0]] if i else [])]
            child = Child("sim_bridge", args, out / f"router{i + 1}.log",
                          program=placement.program(placement.router_site(i), "sim_bridge", args))
            children.append(child)
            watched[f"router{i + 1}"] = child
            child.wait_ready("router listening")
        vehicles = [f"uav{j + 1}" for j in range(uavs)]
        roster = enrol_fleet(out / "fleet-keys", vehicles)
        for vehicle in vehicles:
            (out / vehicle).mkdir(exist_ok=True)
            for stale in (out / vehicle).glob("journal.sqlite*"):
                stale.unlink()
        homes = [local_to_global(GeoOrigin(origin.lat_deg, origin.lon_deg, origin.alt_m), sc.base_x_m, sc.base_y_m, 0.0)
                 for sc in scenarios]
        fence = stub_fence(uavs, defaults.safety.max_altitude_m, home_step_m)
        service_urls = start_stubs(out, vehicles, homes, speedup, placement, children, watched, fence, home_step_m)
        for j, (vehicle, sc) in enumerate(zip(vehicles, scenarios)):
            folder = out / vehicle
            service_url = service_urls[vehicle]
            config = _config({
                **settings,
                "zenoh.mode": zenoh_mode,
                "zenoh.listen": placement.service_endpoint(vehicle) if zenoh_mode == "peer" else "",
                "zenoh.connect": ",".join(routers),
                "zenoh.vehicle": vehicle, "mavlink.url": service_url, "mavlink.start_mission": "true",
                "planner.budget_ms": str(budget_ms), "planner.seed": str(seed + j),
                # a member's first plan waits for its share of the users (the others' claims
                # are not its to count: waiting for all, a late member would never fly)
                "planner.min_requests": str(max(1, users // uavs)), "journal.path": str(folder / "journal.sqlite"),
                "fleet.enabled": "true", "fleet.discovery_s": "1.0", "fleet.roster_file": str(roster),
                "fleet.key_file": str(roster.parent / f"{vehicle}.key"), **scenario_settings(default, sc)})
            (folder / "planner.toml").write_text(to_toml(config))
            args = ["serve", "--config", str(folder / "planner.toml")]
            service = Child("planner_service", args, folder / "service.log",
                            program=placement.program(placement.service_site(vehicle), "planner_service", args))
            children.append(service)
            watched[f"service {vehicle}"] = service
            service.wait_ready("ready:", 120.0)
            echo(f"  {vehicle}: layer {sc.altitude_m:g} m, home {sc.base_x_m:g} m east")
        session = zenoh.open(session_config("client", connect=routers))
        watch = Watch(session, Keys().prefix)
        live.roster = roster
        live.open({vehicle: out / vehicle / "operator.key" for vehicle in vehicles})
        connect = [arg for e in routers for arg in ("--connect", e)]
        children.append(Child("sim_bridge", ["users", "--fleet", *connect, "--count", str(users), "--speedup",
                                             str(speedup), "--seed", str(seed),
                                             *build_config({}, {}).scenario_arguments()], out / "users.log"))
        users_started = time.monotonic()
        cpu_before = {name: cpu_seconds(c.proc.pid) for name, c in watched.items()}
        last_print = 0.0
        while not watch.over(vehicles):
            now = time.monotonic()
            if now - start > timeout_s:
                raise DemoError(f"not every UAV landed within {timeout_s:g} s (landed: {sorted(watch.landed())}); "
                                f"see {out}")
            for child in children:
                if child.proc.poll() is not None and child.name != "sim_bridge users":
                    raise DemoError(f"{child.name} exited with {child.proc.returncode}:\n{child.log()[-1500:]}")
            if now - last_print >= 2.0:
                last_print = now
                echo(_progress(watch, vehicles, now - start))
            if during is not None:
                during(now - users_started)
            time.sleep(0.2)
        flown_s = time.monotonic() - users_started
        usage = process_usage(watched, cpu_before, flown_s)
        time.sleep(0.6)
        watch.close()
        if web:
            live.linger()
    finally:
        live.close()
        if session is not None:
            session.close()
        codes = {f"{c.name} {c.log_path.parent.name}": c.stop() for c in reversed(children)}
    bad = {name: code for name, code in codes.items() if code not in (0, -2, 130)}
    if bad:
        raise DemoError(f"children exited badly: {bad}")
    summary = fleet_summary(out, vehicles, scenarios, base, watch, flown_s)
    summary["processes"] = usage
    with (out / "statuses.jsonl").open("wb") as f:  # for tracing what the summary counts
        f.writelines(encode(s) + b"\n" for v in vehicles for s in watch.statuses[v])
    every = [s for v in vehicles for s in watch.statuses[v]]
    summary["fleet"]["stacked_holds"] = stacked_holds(every, 2 * defaults.safety.hold_radius_m)
    summary["fleet"]["holds_of_two"] = stacked_holds(every, 2 * defaults.safety.hold_radius_m,
                                                     hovering_mps=HOVER_MPS, speedup=speedup)
    summary["fleet"]["users_served_at_once"] = served_at_once(watch.events, speedup)
    summary.update(uavs=uavs, users=users, speedup=speedup, budget_ms=budget_ms, seed=seed, layer_m=LAYER_M,
                   base_step_m=home_step_m, wall_s=time.monotonic() - start)
    if offline:
        planned = offline_fleet(base, users, fleet, seed, budget_ms)
        summary["offline"] = {"algo": OFFLINE_ALGO, **{k: planned[k] for k in (
            "throughput_tasks_per_interval", "intervals", "total_tasks", "users_served", "double_services")}}
        off = planned["throughput_tasks_per_interval"]
        summary["flown_to_offline"] = summary["fleet"]["throughput_tasks_per_interval"] / off if off else None
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    plot_paths(out / "paths.png", base, watch, summary)
    return summary


def stub_fence(uavs: int, max_altitude_m: float, home_step_m: float = BASE_STEP_M) -> list[str]:
    """The stubs' geofence (a stand-in for each autopilot's own), around the fleet's area from
    each UAV's home, the stub's origin: the area grown by the homes' spread east, so that UAV
    j's fence does not start j * ``home_step_m`` east of the area's west edge and refuse the
    points west of that; its ceiling above the highest layer (a raised ceiling raises it)."""
    return ["--fence-alt-max", f"{max(150.0, max_altitude_m + LAYER_M):g}",
            "--fence-margin", f"{FENCE_MARGIN_M + home_step_m * (uavs - 1):g}"]


def start_stubs(out: Path, vehicles: list[str], homes: list[tuple[float, float, float]], speedup: float,
                placement: Placement, children: list[Child], watched: dict[str, Child],
                extra: list[str], home_step_m: float = BASE_STEP_M) -> dict[str, str]:
    """Every UAV's vehicle stub, each once listening: one process each, or all in one
    (``vehicle --count N``: one interpreter for twenty) where the placement says so, their
    homes ``home_step_m`` apart east from the first, ``extra`` arguments to each; the URL each
    service reaches its own by."""
    site = placement.stub_site()
    if placement.stubs_in_one_process and len(vehicles) > 1:
        lat, lon, alt = homes[0]
        args = ["vehicle", "--count", str(len(vehicles)), "--mavlink", placement.stubs_url(), "--speedup",
                str(speedup), "--origin", f"{lat:.7f},{lon:.7f},{alt:.2f}", "--spacing-m", f"{home_step_m:g}", *extra]
        stub = Child("sim_bridge", args, out / "vehicles.log", program=placement.program(site, "sim_bridge", args))
        children.append(stub)
        watched["vehicles"] = stub
        stub.wait_ready(f"{len(vehicles)} vehicles listening", 60.0)
        return {v: placement.vehicle_urls(v, j)[1] for j, v in enumerate(vehicles)}
    urls = {}
    for j, (vehicle, (lat, lon, alt)) in enumerate(zip(vehicles, homes)):
        stub_url, urls[vehicle] = placement.vehicle_urls(vehicle, j)
        args = ["vehicle", "--mavlink", stub_url, "--speedup", str(speedup), "--origin", f"{lat:.7f},{lon:.7f},{alt:.2f}",
                *extra]
        stub = Child("sim_bridge", args, out / vehicle / "vehicle.log", program=placement.program(site, "sim_bridge", args))
        children.append(stub)
        watched[f"vehicle {vehicle}"] = stub
        stub.wait_ready("listening")
    return urls


def process_usage(watched: dict[str, Child], cpu_before: dict[str, float | None], wall_s: float) -> dict[str, Any]:
    """Each watched process's share of one core while the fleet flew, and its peak memory."""
    out = {}
    for name, child in watched.items():
        before, after = cpu_before.get(name), cpu_seconds(child.proc.pid)
        out[name] = {"cpu_percent": None if before is None or after is None else 100.0 * (after - before) / wall_s,
                     "peak_rss_mb": peak_rss_mb(child.proc.pid)}
    return out


def _config(settings: dict[str, str]) -> Any:
    try:
        return build_config({}, settings)
    except ServiceError as err:  # ConfigError: names the key
        raise DemoError(f"configuration: {err}") from None


def _progress(watch: Watch, vehicles: list[str], wall_s: float) -> str:
    with watch.lock:
        parts = []
        for v in vehicles:
            s = watch.statuses[v][-1] if watch.statuses[v] else None
            served = sum(1 for w, e in watch.events if w == v and e.event == "user_served" and not
                         e.detail.startswith("by "))
            parts.append(f"{v} {s.phase if s else '?':8s} {served:2d} served" if s else f"{v} ?")
    return f"[{wall_s:5.1f} s] " + " | ".join(parts)


def fleet_summary(out: Path, vehicles: list[str], scenarios: list[Scenario], base: Scenario, watch: Watch,
                  flown_s: float) -> dict[str, Any]:
    """Each UAV's sortie from its own journal, and the fleet's: throughput the sum of the
    UAVs' (as the offline fleet's), fairness over every service in the order flown, users
    served by two UAVs, and the traffic each member sent on the fleet's keys."""
    per_uav: dict[str, Any] = {}
    merged: list[tuple[float, str, int, int | None]] = []
    for vehicle, sc in zip(vehicles, scenarios):
        journal = Journal(out / vehicle / "journal.sqlite")
        try:
            known = [s.battery_fraction for s in watch.statuses[vehicle] if s.battery_fraction is not None]
            per_uav[vehicle] = sortie_summary(journal, sc, min(known) * sc.battery_j if known else None)
            merged += [(s.time_s, s.user_id, s.tasks, s.bound) for s in journal.services()]
        finally:
            journal.close()
    merged.sort()
    by_user: dict[str, set[str]] = defaultdict(set)
    for vehicle, summary in per_uav.items():
        for user in summary["served"]:
            by_user[user].add(vehicle)
    return {
        "per_uav": per_uav,
        "fleet": {
            "throughput_tasks_per_interval": float(sum(s["throughput_tasks_per_interval"] for s in per_uav.values())),
            "intervals": len(merged),
            "total_tasks": int(sum(t for _, _, t, _ in merged)),
            "users_served": len({u for _, u, _, _ in merged}),
            "users_served_by_two_uavs": sorted(u for u, v in by_user.items() if len(v) > 1),
            "fairness_violations": fairness_violations(base, [(u, b) for _, u, _, b in merged]),
            "energy_violations": sum(bool(s["energy_violation"]) for s in per_uav.values()),
            "requests_accepted": {v: s["requests"]["accepted"] for v, s in per_uav.items()},
        },
        "traffic_bytes_per_s": {v: {"fleet_keys": watch.fleet_bytes[v] / flown_s,
                                    "status": watch.status_bytes[v] / flown_s} for v in vehicles},
        "fleet_keys_by_kind_bytes_per_s": {k: n / flown_s / len(vehicles) for k, n in sorted(watch.fleet_kinds.items())},
    }


def plot_paths(path: Path, scenario: Scenario, watch: Watch, summary: dict[str, Any]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..model import hover_points

    points = hover_points(scenario)
    fig, ax = plt.subplots(figsize=(7, 6.5))
    ax.scatter(points[:, 0], points[:, 1], marker="s", s=30, c="lightgrey", label="hovering points")
    for vehicle, statuses in sorted(watch.statuses.items()):
        flown = [s for s in statuses if s.phase != "lost"]
        line, = ax.plot([s.x_m for s in flown], [s.y_m for s in flown], "-", lw=1.2,
                        label=f"{vehicle}: {summary['per_uav'][vehicle]['intervals']} services")
        ax.scatter([s.x_m for s in flown[:1]], [s.y_m for s in flown[:1]], marker="^", color=line.get_color(), s=60)
    area_axes(ax, scenario.area_side_m)
    f = summary["fleet"]
    ax.set_title(f"{len(watch.statuses)} UAVs: {f['intervals']} services to {f['users_served']} users, "
                 f"{f['throughput_tasks_per_interval']:.1f} tasks/interval (fleet)")
    ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


__all__ = ["run_fleet_demo", "fleet_of", "scenario_settings"]
