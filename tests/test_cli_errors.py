"""The command lines' edges, as a user hits them: every error of ``python -m planner_service``
and ``python -m sim_bridge`` is one line on stderr naming the option, exit status 2, no
traceback, and nothing starts (a bad zenoh endpoint, a bad MAVLink URL such as
``--mavlink bogus:1``, which the service used to accept and then wait on for ever, a bad
number, a missing file). A file that is not a journal is refused at start the same way,
with exit status 1 (the command line was right; the file is not), and so is a journal that
cannot be created or written: on a full file system (a real tmpfs filled up, where this
user may mount one) or where the kernel refuses the writes (RLIMIT_FSIZE), one line saying
so, never a traceback, and an existing journal left as it was."""

from __future__ import annotations

import resource
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

PS, SB = "planner_service", "sim_bridge"
SUBMIT = ("submit", "--user", "u", "--x", "1", "--y", "2", "--tasks", "3")

CASES: list[tuple[str, tuple[str, ...], str]] = [
    # (module, arguments, what the one line must say)
    (PS, ("serve", "--mavlink", "bogus:1"), "--mavlink (mavlink.url): 'bogus:1' has no known scheme ('bogus')"),
    (PS, ("serve", "--mavlink", "udpin:127.0.0.1:99999"), "--mavlink (mavlink.url): 'udpin:127.0.0.1:99999': port 99999"),
    (PS, ("serve", "--mavlink", "/dev/no-such-tty,57600"), "--mavlink (mavlink.url): '/dev/no-such-tty,57600': no such "
                                                            "serial device"),
    (PS, ("serve", "--set", "mavlink.url=udpout:localhost"), "mavlink.url: 'udpout:localhost': after the scheme comes "
                                                              "HOST:PORT"),
    (PS, ("serve", "--listen", "bogus"), "argument --listen: 'bogus' is not a zenoh endpoint"),
    (PS, ("serve", "--set", "zenoh.connect=tcp/127.0.0.1"), "zenoh.connect: 'tcp/127.0.0.1': the address must be "
                                                             "HOST:PORT"),
    (PS, ("serve", "--listen", "foo/127.0.0.1:7447"), "argument --listen: 'foo/127.0.0.1:7447': 'foo' is not a zenoh "
                                                      "link protocol"),
    (PS, ("serve", "--config", "missing.toml"), "argument --config: missing.toml: no such file"),
    (PS, ("serve", "--zenoh-config", "missing.json5"), "argument --zenoh-config: missing.json5: no such file"),
    (PS, ("serve", "--set", "planner.budget_ms=fast"), "planner.budget_ms: cannot read 'fast' as float"),
    (PS, ("serve", "--backend", "ros"), "argument --backend: invalid choice: 'ros'"),
    (PS, ("serve", "--log-level", "LOUD"), "argument --log-level: invalid choice: 'LOUD'"),
    (PS, (*SUBMIT, "--connect", "bogus"), "argument --connect: 'bogus' is not a zenoh endpoint"),
    (PS, (*SUBMIT, "--connect", "tcp/127.0.0.1:70000"), "argument --connect: 'tcp/127.0.0.1:70000': port 70000"),
    (PS, ("submit", "--user", "u", "--x", "abc", "--y", "2", "--tasks", "3"), "argument --x: 'abc' is not a number"),
    (PS, ("submit", "--user", "u", "--x", "nan", "--y", "2", "--tasks", "3"), "argument --x: 'nan' is not a finite"),
    (PS, ("submit", "--user", "u", "--x", "1", "--y", "2", "--tasks", "-3"), "argument --tasks: -3 is negative"),
    (PS, (*SUBMIT, "--zenoh-config", "missing.json5"), "argument --zenoh-config: missing.json5: no such file"),
    (PS, (*SUBMIT, "--prefix", "a/*"), "argument --prefix: 'a/*' is not a key chunk"),
    (PS, (*SUBMIT, "--timeout", "0"), "argument --timeout: 0 is not positive"),
    (PS, ("submit", "--user", "u"), "the following arguments are required: --x, --y, --tasks"),
    (PS, ("operator", "fly"), "argument action: invalid choice: 'fly'"),
    (PS, ("operator", "start", "--connect", "tls/uav1.local"), "argument --connect: 'tls/uav1.local': the address "
                                                               "must be HOST:PORT"),
    (PS, ("operator", "status", "--reason", "x"), "--reason: only start and hold take a reason, not status"),
    (PS, ("operator", "start", "--reason", "x" * 300), "--reason: 300 characters; at most 256"),
    (PS, ("operator", "watch", "--refresh", "-1"), "argument --refresh: -1 is not positive"),
    (PS, ("plan", "--iterations", "many"), "argument --iterations: invalid int value: 'many'"),
    (PS, ("plan", "--uavs", "0"), "--uavs: uavs: must lie in (0, 64], got 0"),
    (PS, ("plan", "--uavs", "2", "--layer-m", "-1"), "--layer-m: layer_m: must not be negative, got -1"),
    (PS, ("plan", "--uavs", "2", "--algo", "mcts"), "--algo mcts plans one UAV; with --uavs choose from ['claims', "
                                                    "'dec-mcts', 'independent', 'joint']"),
    (PS, ("plan", "--uavs", "2", "--algo", "dec-mcts", "--msg-drop", "2"), "--msg-drop: drop must lie in [0, 1], "
                                                                           "got 2.0"),
    (PS, ("plan", "--uavs", "2", "--algo", "claims", "--msg-age", "1"), "--msg-drop and --msg-age are dec-mcts's "
                                                                        "messages: give --algo dec-mcts"),
    (PS, ("plan", "--algo", "claims"), "--algo claims plans a fleet: give --uavs N"),
    (PS, ("demo", "--users", "0"), "argument --users: 0 is not at least 1"),
    (PS, ("bench", "--web"), "error: --web goes with --e2e"),
    (PS, ("bench", "--scale"), "error: --scale goes with --fleet"),
    (PS, ("bench", "--fleet", "--scale", "--loss", "1.5"), "--loss in [0, 1)"),
    (PS, ("bench", "--fleet", "--scale", "--uavs", "5,x"), "--uavs '5,x' is not a number list"),
    (PS, ("bench", "--fleet", "--scale", "--uavs", "50"), "--uavs 1 to 40 each"),
    (PS, ("operator", "web", "--listen", "0.0.0.0:8765"), "--tls-cert and --tls-key, or listen on 127.0.0.1"),
    (PS, ("operator", "web", "--origin", "91,0"), "--origin: '91,0' is not LAT,LON"),
    (PS, ("operator", "watch", "--tiles", "x"), "are for web"),
    (PS, ("fly",), "argument COMMAND: invalid choice: 'fly'"),
    (SB, ("vehicle", "--mavlink", "bogus:1"), "argument --mavlink: 'bogus:1' is not udpin:HOST:PORT"),
    (SB, ("vehicle", "--mavlink", "udpin:127.0.0.1:99999"), "argument --mavlink: port 99999 is out of range"),
    (SB, ("vehicle", "--speedup", "-2"), "argument --speedup: -2 is not positive"),
    (SB, ("vehicle", "--sysid", "300"), "argument --sysid: 300 is not a MAVLink system id"),
    (SB, ("wire", "--link", "l=ns1:t0,ns2:t1,100"), "expected NAME=NS_A:DEV_A,NS_B:DEV_B,DELAY_MS,JITTER_MS,LOSS"),
    (SB, ("wire", "--link", "l=-:nosuchtun0,-:nosuchtun1,1,0,0"), "TUN device 'nosuchtun0' in this namespace"),
    (SB, ("users", "--connect", "bogus"), "argument --connect: 'bogus' is not a zenoh endpoint"),
    (SB, ("users", "--count", "0"), "argument --count: 0 is not at least 1"),
    (SB, ("router", "--listen", "bogus"), "argument --listen: 'bogus' is not a zenoh endpoint"),
    (SB, ("router", "--listen", "tcp/127.0.0.1:7447", "--zenoh-config", "missing.json5"),
     "argument --zenoh-config: missing.json5: no such file"),
    (SB, ("lossy-proxy", "--listen", "127.0.0.1:1", "--forward", "127.0.0.1:2", "--drop", "2"),
     "argument --drop: 2 is not a probability in [0, 1]"),
    (SB, ("lossy-proxy", "--listen", "bogus", "--forward", "127.0.0.1:2"), "--listen: 'bogus' is not HOST:PORT"),
]


def run(module: str, args: tuple[str, ...], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", module, *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=120)


def test_every_command_line_error_is_one_line_naming_the_option(tmp_path: Path, python_env: dict[str, str]) -> None:
    with ThreadPoolExecutor(4) as pool:
        done = list(pool.map(lambda case: run(case[0], case[1], tmp_path, python_env), CASES))
    bad = []
    for (module, args, words), out in zip(CASES, done):
        lines = out.stderr.strip().splitlines()
        ok = (out.returncode == 2 and len(lines) == 1 and words in lines[0] and "Traceback" not in out.stderr
              and out.stdout == "")
        if not ok:
            bad.append(f"{module} {' '.join(args)[:80]}: exit {out.returncode}, stderr {out.stderr[-600:]!r}")
    assert not bad, "\n".join(bad)
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing started, no journal made


@pytest.mark.parametrize("content", [b"", b"name,value\n", b"SQLite format 3\x00" + b"\x00" * 200])
def test_a_file_that_is_not_a_journal_stops_the_service_at_start(tmp_path: Path, python_env: dict[str, str],
                                                                  content: bytes) -> None:
    journal = tmp_path / "journal.sqlite"
    journal.write_bytes(content)
    out = run(PS, ("serve", "--journal", str(journal), "--mavlink", "udpout:127.0.0.1:9", "--listen",
                   "tcp/127.0.0.1:9"), tmp_path, python_env)
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 1 and len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    assert lines[0].startswith(f"error: {journal} is not a journal"), lines
    assert journal.read_bytes() == content  # left as it was


SERVE_AT = ("--mavlink", "udpout:127.0.0.1:9", "--listen", "tcp/127.0.0.1:9")
MAKE_JOURNAL = "import sys; from planner_service.service.journal import Journal; Journal(sys.argv[1]).close()"
TMPFS = "256k"
"""Room for a journal (about 60 kB while it is made), then filled up."""
FILL_AND_SERVE = """
mount -t tmpfs -o size="$6" tmpfs "$1" || exit 99
cd "$2"
if [ "$3" = existing ]; then "$4" -c "$5" "$1/journal.sqlite" && sha256sum "$1/journal.sqlite"; fi
dd if=/dev/zero of="$1/fill" bs=4k 2>/dev/null
"$4" -m planner_service serve --journal "$1/journal.sqlite" --mavlink udpout:127.0.0.1:9 --listen tcp/127.0.0.1:9
status=$?
if [ "$3" = existing ]; then sha256sum "$1/journal.sqlite"; fi
ls -A "$1"
exit $status
"""


def one_line_error(out: subprocess.CompletedProcess[str]) -> str:
    """The one line a start refused by the journal prints (status 1, no traceback)."""
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 1 and len(lines) == 1 and "Traceback" not in out.stderr, (out.returncode, out.stderr)
    return lines[0]


@pytest.mark.parametrize("journal", ["new", "existing"])
def test_a_journal_on_a_full_file_system_stops_the_service_at_start(tmp_path: Path, python_env: dict[str, str],
                                                                    journal: str) -> None:
    mount = tmp_path / "tiny"
    mount.mkdir()
    unshare = shutil.which("unshare")
    probe = subprocess.run([unshare or "unshare", "-m", "mount", "-t", "tmpfs", "-o", f"size={TMPFS}", "tmpfs",
                            str(mount)], capture_output=True, text=True) if unshare else None
    if probe is None or probe.returncode != 0:
        pytest.skip("cannot mount a tmpfs in a private mount namespace here (needs unshare and CAP_SYS_ADMIN)")
    out = subprocess.run(["unshare", "-m", "sh", "-c", FILL_AND_SERVE, "sh", str(mount), str(tmp_path), journal,
                          sys.executable, MAKE_JOURNAL, TMPFS], env=python_env, capture_output=True, text=True,
                         timeout=120)
    line = one_line_error(out)
    path = mount / "journal.sqlite"
    print(f"\n{journal}: {line}")
    if journal == "new":
        assert line.startswith(f"error: cannot create the journal {path}: the disk (or the database's size limit) "
                               "is full (SQLITE_FULL"), line
        assert out.stdout.split() == ["fill"]  # nothing half-made left, nothing kept from the space
    else:
        assert line.startswith(f"error: cannot open the journal {path}: "), line  # not "is not a journal"
        before, _, after, _, *names = out.stdout.split()
        assert before == after and "journal.sqlite" in names  # left as it was
    assert line.endswith("; 0 bytes free on its file system"), line


@pytest.mark.parametrize("journal", ["new", "existing"])
def test_a_journal_the_kernel_refuses_to_write_stops_the_service_at_start(tmp_path: Path, python_env: dict[str, str],
                                                                         journal: str) -> None:
    path = tmp_path / "journal.sqlite"
    if journal == "existing":
        subprocess.run([sys.executable, "-c", MAKE_JOURNAL, str(path)], env=python_env, check=True, timeout=60)
    before = path.read_bytes() if journal == "existing" else None

    def no_writes() -> None:  # the child's every write to a file past byte 0 fails (EFBIG)
        resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))

    out = subprocess.run([sys.executable, "-m", PS, "serve", "--journal", str(path), *SERVE_AT], cwd=tmp_path,
                         env=python_env, capture_output=True, text=True, timeout=120, preexec_fn=no_writes)
    line = one_line_error(out)
    print(f"\n{journal}: {line}")
    verb = "create" if journal == "new" else "open"
    assert line.startswith(f"error: cannot {verb} the journal {path}: an I/O error (SQLITE_IOERR"), line
    if journal == "new":
        assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing half-made left
    else:
        assert path.read_bytes() == before
