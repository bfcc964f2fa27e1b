"""Hunt flaky tests: run chosen tests N times, optionally beside CPU-bound processes, and
print each test's pass rate (docs/TESTING.md).

    python -m tests.flakes --runs 5 --hogs 2 tests/service/test_faults.py::test_sortie_over_a_lossy_link

Each run is one pytest process (the tests in it one after another) with its own
``--basetemp`` under ``--keep``, so a failure's processes' logs, journals and tracks are
there to read afterwards; of the runs that passed only pytest's output is kept. A hog is a process that spins
on one core for as long as the hunt lasts: two of them on this two-core machine leave the
tests what a busy CI machine leaves them.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def _spin() -> None:
    while True:
        pass


def outcomes(junit: Path) -> dict[str, str]:
    """Test id -> "passed", "failed" or "skipped", read from pytest's JUnit XML."""
    result: dict[str, str] = {}
    for case in ET.parse(junit).getroot().iter("testcase"):
        path = case.get("classname", "").replace(".", "/")
        test_id = f"{path}.py::{case.get('name')}"
        kinds = {child.tag for child in case}
        result[test_id] = ("failed" if kinds & {"failure", "error"} else
                           "skipped" if "skipped" in kinds else "passed")
    return result


def _run(cmd: list[str]) -> str:
    """One pytest run's output; interrupted, its process group is killed with it (the
    test processes it started die with it: planner_service.harness.processes)."""
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        out, _ = proc.communicate()
        return out
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def hunt(tests: list[str], runs: int, hogs: int, keep: Path, pytest_args: list[str]) -> dict[str, list[str]]:
    """Every test's outcome in every run, in order."""
    spinners = [multiprocessing.Process(target=_spin, daemon=True) for _ in range(hogs)]
    for s in spinners:
        s.start()
    seen: dict[str, list[str]] = defaultdict(list)
    try:
        for k in range(1, runs + 1):
            folder = keep / f"run-{k}"
            folder.mkdir(parents=True, exist_ok=True)
            junit = folder / "junit.xml"
            t0 = time.monotonic()
            # -p no:randomly and friends are not installed; the order is the one given
            cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "",
                   f"--basetemp={folder / 'tmp'}", f"--junitxml={junit}", *pytest_args, *tests]
            (folder / "pytest.log").write_text(_run(cmd))
            found = outcomes(junit) if junit.exists() else {}
            for test_id, outcome in found.items():
                seen[test_id].append(outcome)
            failed = sorted(t for t, o in found.items() if o == "failed")
            print(f"run {k}/{runs}: {time.monotonic() - t0:.0f} s, "
                  f"{'failed: ' + ', '.join(failed) if failed else 'all passed' if found else 'no results'}",
                  flush=True)
            if not failed and found:
                shutil.rmtree(folder / "tmp")  # the output stays: its printed figures
    finally:
        for s in spinners:
            s.terminate()
    return seen


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.flakes", description=__doc__.split("\n\n")[0])
    parser.add_argument("tests", nargs="+", help="pytest node ids or files")
    parser.add_argument("--runs", type=int, default=5, help="how many times to run them (default 5)")
    parser.add_argument("--hogs", type=int, default=0, help="CPU-bound processes beside the tests (default 0)")
    parser.add_argument("--keep", type=Path, default=None,
                        help="where the failed runs' files are kept (default: a new folder in /tmp)")
    parser.add_argument("--pytest-args", default="", help="more pytest arguments, one string")
    args = parser.parse_args(argv)
    if args.runs < 1 or args.hogs < 0:
        parser.error("--runs must be at least 1 and --hogs at least 0")
    keep = args.keep or Path(tempfile.mkdtemp(prefix="flakes-"))
    print(f"{args.runs} runs beside {args.hogs} hogs; failed runs kept in {keep}", flush=True)
    seen = hunt(args.tests, args.runs, args.hogs, keep, args.pytest_args.split())
    print(f"\n{'passed':>8}  test")
    worst = 1.0
    for test_id, results in sorted(seen.items()):
        ran = [r for r in results if r != "skipped"]
        rate = f"{ran.count('passed')}/{len(ran)}" if ran else "skipped"
        worst = min(worst, ran.count("passed") / len(ran)) if ran else worst
        print(f"{rate:>8}  {test_id}")
    return 0 if seen and worst == 1.0 else 1


if __name__ == "__main__":
    sys.exit(main())
