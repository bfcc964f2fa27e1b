"""The demo sortie: vehicle stub, users and service as real processes on loopback, watched
over zenoh; then the summary, the trajectory figure and the mission file. With ``mavlink``
the service flies an external autopilot at that address (ArduCopter SITL, a real one)
instead of the stub; ``config`` is a service configuration to start from (its scenario,
safety margins and planner settings: docs/sitl-copter.toml for ArduCopter SITL)."""

from __future__ import annotations

import json
import socket
import threading
import time
import tomllib
from pathlib import Path
from typing import Any, Callable

from protocol import Event, Status, write_plan
from protocol.client import PlannerClient

from ..service.config import build_config, to_toml
from ..service.errors import ServiceError
from ..service.journal import Journal
from ..service.sortie import item_from_dict
from .live_map import LiveMap
from .offline import plan_offline
from .processes import Child, free_port, start_vehicle_and_service
from .report import sortie_summary


class DemoError(ServiceError):
    """The demo could not fly its sortie."""


def run_demo(out: Path, *, users: int = 10, speedup: float = 25.0, budget_ms: float = 150.0,
             backend: str = "pymavlink", flavour: str | None = None, seed: int = 1, timeout_s: float = 180.0,
             mavlink: str | None = None, config: Path | None = None, algo: str = "mcts", offline: bool = True,
             echo: Callable[[str], None] = print, web: bool = False) -> dict[str, Any]:
    """Fly one sortie; returns the summary (also written to ``out/summary.json``). With
    ``mavlink`` (a connection string) no stub is started: the service flies the autopilot there
    (SITL or a real one), and ``speedup`` must be that autopilot's (the users' clock runs at it).
    With ``offline`` the same scenario and seed are also planned offline (the model alone,
    ``offline.py``, ``bench --flight``'s other half) and the summary says how the flown sortie compares.
    The live map's address is printed once the service is up; with ``web`` the page (and the
    service) stay until Ctrl-C after the landing."""
    out.mkdir(parents=True, exist_ok=True)
    journal_path = out / "journal.sqlite"
    for stale in (journal_path, out / "journal.sqlite-wal", out / "journal.sqlite-shm"):
        stale.unlink(missing_ok=True)
    zenoh_port, mav_port = free_port(), free_port(socket.SOCK_DGRAM)
    endpoint = f"tcp/127.0.0.1:{zenoh_port}"
    try:
        base = _read_toml(config) if config is not None else {}
        flavour = flavour or str(base.get("mavlink", {}).get("flavour", "ardupilot"))
        service_config = build_config(base, {
            "zenoh.listen": endpoint, "mavlink.url": mavlink or f"udpout:127.0.0.1:{mav_port}",
            "mavlink.backend": backend, "mavlink.flavour": flavour, "mavlink.start_mission": "true",
            "planner.budget_ms": str(budget_ms), "planner.algo": algo, "planner.seed": str(seed),
            "journal.path": str(journal_path),
            "planner.min_requests": str(users),  # the first plan sees every user
        })
    except ServiceError as err:  # ConfigError: names the key
        raise DemoError(f"configuration: {err}") from None
    config_path = out / "planner.toml"
    config_path.write_text(to_toml(service_config))
    scenario = service_config.scenario()
    scenario_args = service_config.scenario_arguments()  # the users draw from the service's model
    children: list[Child] = []
    statuses: list[Status] = []
    events: list[Event] = []
    landed = threading.Event()
    start = time.monotonic()
    live = LiveMap([endpoint], service_config.keys().prefix, echo=echo)
    try:
        vehicle = f"the autopilot at {mavlink}" if mavlink else f"vehicle stub ({flavour}, x{speedup:g})"
        echo(f"demo: {vehicle}, service ({backend}, {budget_ms:g} ms), {users} users at x{speedup:g}; logs in {out}")
        stub = None if mavlink else ["--mavlink", f"udpin:127.0.0.1:{mav_port}", "--flavour", flavour,
                                     "--speedup", str(speedup)]
        start_vehicle_and_service(out, stub, children)
        with PlannerClient([endpoint], service_config.keys()) as client:
            if not client.wait_for_service(20.0):
                raise DemoError("the service's liveliness token never appeared")
            live.open({service_config.keys().vehicle: out / "operator.key"})

            def on_event(ev: Event) -> None:
                events.append(ev)
                if ev.event == "user_served":
                    echo(f"  served {ev.user_id}: {ev.detail}")
                elif ev.event in ("returning", "landed", "upload_failed", "link_lost"):
                    echo(f"  {ev.event}: {ev.detail}")
                if ev.event == "landed":
                    landed.set()

            client.follow_events(on_event)
            client.follow_status(statuses.append)
            children.append(Child("sim_bridge", ["users", "--count", str(users), "--speedup", str(speedup),
                                                 "--seed", str(seed), "--connect", endpoint, *scenario_args],
                                  out / "users.log"))
            last_print = 0.0
            while not landed.wait(0.2):
                now = time.monotonic()
                if now - start > timeout_s:
                    raise DemoError(f"no landing within {timeout_s:g} s; see {out}/service.log")
                for child in children:
                    if child.proc.poll() is not None and child.name != "sim_bridge users":
                        raise DemoError(f"{child.name} exited with {child.proc.returncode}:\n{child.log()[-1500:]}")
                if now - last_print >= 1.0 and statuses:
                    last_print = now
                    echo(_progress_line(statuses[-1], events, now - start))
            time.sleep(0.6)  # the last status publications after the landing
            if web:
                live.linger()
    finally:
        live.close()
        codes = {child.name: child.stop() for child in reversed(children)}
    wall = time.monotonic() - start
    bad = {name: code for name, code in codes.items() if code not in (0, -2, 130)}
    if bad:
        raise DemoError(f"children exited badly: {bad}")
    journal = Journal(journal_path)
    try:
        known = [st.battery_fraction for st in statuses if st.battery_fraction is not None]  # None: unknown
        # the lowest, not the last: PX4 SITL's battery is full again as soon as it disarms
        final_battery = min(known) * scenario.battery_j if known else None
        # The sortie that landed: an autopilot whose battery is full again at disarming (PX4
        # SITL) lets the next sortie begin before the demo stops.
        flown = [row.number for row in journal.sorties() if row.over]
        summary = sortie_summary(journal, scenario, final_battery, flown[-1] if flown else None)
        summary.update(preset=scenario.name, algo=algo, backend=backend, flavour=flavour, users=users,
                       speedup=speedup, budget_ms=budget_ms, seed=seed, wall_s=wall, scenario=scenario.as_dict(),
                       config=str(config_path), autopilot=mavlink or "stub")
        missions = [m for m in journal.missions() if m.result == "accepted" and m.points]
        if missions:
            items = [item_from_dict(i) for i in missions[0].items]
            (out / "mission.plan").write_text(write_plan(items, flavour, service_config.origin_point()))  # type: ignore[arg-type]
        requests = journal.requests()
        services = journal.services()
    finally:
        journal.close()
    if offline:
        planned = plan_offline(algo, seed, users, budget_ms, lambda _: None, scenario)
        summary["offline"] = {k: planned[k] for k in ("intervals", "throughput_tasks_per_interval", "average_reward",
                                                      "total_tasks")}
        summary["flown_to_offline"] = (summary["throughput_tasks_per_interval"] / planned["throughput_tasks_per_interval"]
                                       if planned["throughput_tasks_per_interval"] else None)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    plot_trajectory(out / "trajectory.png", scenario, statuses, requests, services, summary)
    return summary


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except OSError as err:
        raise DemoError(f"cannot read the configuration {path}: {err.strerror or err}") from None
    except tomllib.TOMLDecodeError as err:
        raise DemoError(f"{path} is not valid TOML: {err}") from None


def _progress_line(s: Status, events: list[Event], wall_s: float) -> str:
    served = [e for e in events if e.event == "user_served"]
    tasks = sum(int(e.detail.split()[0]) for e in served if e.detail.split() and e.detail.split()[0].isdigit())
    users = len({e.user_id for e in served})
    per = tasks / len(served) if served else 0.0
    battery = "  ?" if s.battery_fraction is None else f"{s.battery_fraction:4.0%}"
    return (f"[{wall_s:5.1f} s] {s.phase:9s} {s.mode:12s} battery {battery}  "
            f"at ({s.x_m:5.0f}, {s.y_m:5.0f}, {s.z_m:4.0f}) m  served {users} users / {len(served)} services, "
            f"{per:.1f} tasks/interval  pending {s.pending_requests}")


def plot_trajectory(path: Path, scenario: Any, statuses: list[Status], requests: list[Any], services: list[Any],
                    summary: dict[str, Any]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..model import hover_points

    points = hover_points(scenario)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5.5), gridspec_kw={"width_ratios": [1.2, 1]})
    ax.scatter(points[:, 0], points[:, 1], marker="s", s=30, c="lightgrey", label="hovering points")
    ax.scatter([r.x_m for r in requests], [r.y_m for r in requests], s=6, c="tab:blue", alpha=0.3,
               label="user requests")
    xs = [s.x_m for s in statuses if s.phase != "lost"]
    ys = [s.y_m for s in statuses if s.phase != "lost"]
    ax.plot(xs, ys, "-", c="tab:red", lw=1.2, label="UAV track (status)")
    for n, s in enumerate(services, 1):
        ax.annotate(str(n), (s.x_m, s.y_m), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.scatter([s.x_m for s in services], [s.y_m for s in services], c="tab:red", s=40, zorder=3, label="services")
    area_axes(ax, scenario.area_side_m)
    ax.set_title(f"{summary['intervals']} services to {summary['served_users']} users, "
                 f"{summary['throughput_tasks_per_interval']:.1f} tasks/interval")
    ax.legend(loc="upper right", fontsize=7)
    if statuses:
        t0 = statuses[0].time_s
        bx.plot([s.time_s - t0 for s in statuses],
                [float("nan") if s.battery_fraction is None else 100 * s.battery_fraction for s in statuses],
                c="tab:green")  # an unknown reading is a gap
    bx.axhline(100 * scenario.battery_threshold, ls="--", c="grey", label="reserve threshold")
    bx.set_xlabel("wall time (s)")
    bx.set_ylabel("battery (%)")
    bx.set_ylim(0, 102)
    bx.legend(fontsize=7)
    bx.set_title("battery")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def area_axes(ax: Any, side_m: float) -> None:
    """The area's square, metres east and north, with a margin."""
    ax.set_xlim(-20, side_m + 20)
    ax.set_ylim(-20, side_m + 20)
    ax.set_aspect("equal")
    ax.set_xlabel("x east (m)")
    ax.set_ylabel("y north (m)")


__all__ = ["DemoError", "area_axes", "run_demo", "plot_trajectory"]
