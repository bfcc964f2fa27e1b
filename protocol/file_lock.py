"""An exclusive ``flock`` on a file and what can be known of it, shared by the journal and
the signing timestamp file (each takes the lock on the file itself, never on a file beside
it: nothing can be deleted to get round it, and the kernel drops it with its process)."""

from __future__ import annotations

import errno
import fcntl
import os


def lock_or_holder(fd: int) -> str | None:
    """Lock the file open as ``fd`` exclusively, without waiting: None once locked; if
    another process holds it, who (``pid N`` where ``/proc/locks`` shows it), and ``fd`` is
    closed. Any other failure closes ``fd`` and raises its ``OSError``."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as err:
        holder = flock_holder(fd)
        os.close(fd)
        if err.errno not in (errno.EWOULDBLOCK, errno.EAGAIN):
            raise
        return f"pid {holder}" if holder else "another process"
    return None


def names(path: str, fd: int) -> bool:
    """True if ``path`` still leads to the file open as ``fd`` (a lock taken on a file that
    was removed or replaced meanwhile guards nothing)."""
    try:
        now = os.stat(path)
    except OSError:
        return False
    held = os.fstat(fd)
    return (now.st_dev, now.st_ino) == (held.st_dev, held.st_ino)


def flock_holder(fd: int) -> int | None:
    """The pid that holds a ``flock`` on the file open as ``fd``, as ``/proc/locks`` shows
    it; None where it does not (another system, another pid namespace)."""
    info = os.fstat(fd)
    device = f"{os.major(info.st_dev):02x}:{os.minor(info.st_dev):02x}:{info.st_ino}"
    try:
        with open("/proc/locks") as handle:
            lines = handle.read().splitlines()
    except OSError:
        return None
    for line in lines:
        fields = line.split()  # "1: FLOCK ADVISORY WRITE 4242 fe:00:1234 0 EOF"; waiters have "->"
        if len(fields) >= 6 and fields[1] == "FLOCK" and fields[5] == device and fields[4].isdigit():
            pid = int(fields[4])
            if pid > 0:
                return pid
    return None
