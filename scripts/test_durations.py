#!/usr/bin/env python
"""tests/durations.json from a whole run of the suite: ``./scripts/test.sh --durations=0 | python
scripts/test_durations.py``. The seconds each test file took (its tests' set-up, call and tear-down), which the
suite's workers take heaviest first (tests/conftest.py); a file missing from it counts as the median file.
Stale figures only change the order in which the files run."""

import json
import os
import re
import sys
from collections import defaultdict

LINE = re.compile(r"^([0-9.]+)s (?:setup|call|teardown)\s+(tests/\S+?\.py)::")


def main() -> int:
    seconds: dict[str, float] = defaultdict(float)
    for line in sys.stdin:
        m = LINE.match(line)
        if m:
            seconds[m.group(2)] += float(m.group(1))
    if not seconds:
        print("test_durations: no '--durations=0' lines on standard input", file=sys.stderr)
        return 1
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests", "durations.json")
    with open(path, "w") as fh:
        json.dump({k: round(v, 1) for k, v in sorted(seconds.items())}, fh, indent=0)
        fh.write("\n")
    print(f"test_durations: {len(seconds)} files, {sum(seconds.values()):.0f} s -> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
