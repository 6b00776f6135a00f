"""`python -m bench.compaction RAW.h5`: compress a closed raw file's streams (bench.recorder.compact),
the detached process `gyrobench run` leaves this to so that it returns without waiting for it."""

from __future__ import annotations

import sys


def main(argv: list[str]) -> int:
    """Compact each file named; 0 when every one was replaced, 1 when one was left as written."""
    from bench.recorder import STREAM_FILTERS, compact

    ok = all(compact(path, STREAM_FILTERS) for path in argv)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
