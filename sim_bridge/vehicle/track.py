"""The vehicle's own flight log (``--track``): where it really was, in simulated time, as an
autopilot's dataflash log records its position. Tests compare what the service recorded as
flown (a hold at a point) with this, not with what the service believed.

CSV, one line a tick: ``time_s,x_m,y_m,z_m,seq,mode,armed`` (simulated seconds of the
flight, local metres east/north/up of the origin, the mission item flown, the mode's name,
0/1). Appended, so a vehicle restarted with ``--state-file`` goes on in the same file (its
time goes on from the saved flight); flushed every line, so a vehicle killed mid-flight (a
fault test's SIGKILL) loses none of what it flew.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Iterator

from .flight import Flight

HEADER = ("time_s", "x_m", "y_m", "z_m", "seq", "mode", "armed")


@dataclass(frozen=True)
class TrackPoint:
    time_s: float
    xyz: tuple[float, float, float]
    seq: int
    mode: str
    armed: bool


class Track:
    def __init__(self, path: Path) -> None:
        fresh = not path.exists() or path.stat().st_size == 0
        self._file: IO[str] = open(path, "a", newline="")
        self._csv = csv.writer(self._file)
        if fresh:
            self._csv.writerow(HEADER)

    def write(self, flight: Flight) -> None:
        x, y, z = flight.pos
        self._csv.writerow((f"{flight.time_s:.3f}", f"{x:.3f}", f"{y:.3f}", f"{z:.3f}", flight.current,
                            flight.mode.value, int(flight.armed)))
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def read_track(path: Path) -> Iterator[TrackPoint]:
    """The points of a track file, in order."""
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            yield TrackPoint(float(row["time_s"]), (float(row["x_m"]), float(row["y_m"]), float(row["z_m"])),
                             int(row["seq"]), row["mode"], row["armed"] == "1")
