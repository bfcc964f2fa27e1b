import signal
import sys

from .cli import main

status = main()
# Done: a stop asked while the interpreter finalises (zenoh's threads take a moment) is
# ignored. CPython puts back the default handler of every signal Python handled as it
# exits (not an ignored one), so a SIGINT then killed a run that had ended well (-2).
for sig in (signal.SIGINT, signal.SIGTERM):
    signal.signal(sig, signal.SIG_IGN)
sys.exit(status)
