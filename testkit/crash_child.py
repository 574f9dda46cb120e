"""The crash trials' child: inspections back to back, to be killed at any moment.

``python -m testkit.crash_child DATA_DIR N PREFIX [DB_URL]`` opens a session on the
twins as the station does (the store in ``DATA_DIR``, or at ``DB_URL``), prints
``ready``, then inspects ``N`` parts with serials ``PREFIX-00``, ``PREFIX-01``, ...
It prints ``done ID STATE RESULT`` only after ``inspect`` returned, i.e. after the
commit: every printed id is an acknowledged result, which the parent
(``testkit.crash``) must find in the store after a SIGKILL.
"""

from __future__ import annotations

import asyncio
import sys

from testkit.session import FRAMES_PER_HOLE, PART, TIME_SCALE, use_small_frame


async def inspect_parts(data_dir: str, n: int, prefix: str, db_url: str | None) -> None:
    from station.inspection.scan import ScanSettings
    from station.parts import load_part
    from station.runtime import open_session

    spec = load_part(PART)
    async with open_session(time_scale=TIME_SCALE, data_dir=data_dir, db_url=db_url,
                            settings=ScanSettings(frames_per_hole=FRAMES_PER_HOLE)) as s:
        use_small_frame(s)
        print("ready", flush=True)
        for i in range(n):
            out = await s.inspect(spec, f"{prefix}-{i:02d}")
            print("done", out.id, out.state, out.result, flush=True)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) not in (3, 4):
        print(__doc__, file=sys.stderr)
        return 2
    asyncio.run(inspect_parts(args[0], int(args[1]), args[2], args[3] if len(args) > 3 else None))
    return 0


if __name__ == "__main__":
    sys.exit(main())
