"""The end of a sweep removes only idle work folders: two sweep processes on one output folder
(one per core) must not delete each other's running attempts. (Before this, the first sweep to
finish removed the whole ``.work`` folder and a running Diffusion-AC seed with it.)"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from cdr_bench.scale.sweep import remove_idle_work


def test_live_attempts_survive_and_idle_ones_go(tmp_path: Path) -> None:
    out = tmp_path / "out"
    idle, dead, live = (out / ".work" / n for n in ("k1-idle", "k2-dead", "k3-live"))
    for d in (idle, dead, live):
        d.mkdir(parents=True)
        (d / "state.pt").write_bytes(b"x")
    (dead / ".lock").write_text("")  # a lock file nobody holds: its attempt died
    (live / ".lock").write_text("")
    fd = os.open(live / ".lock", os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX)  # the running attempt of another sweep process
    try:
        remove_idle_work(out)
        assert not idle.exists() and not dead.exists()
        assert (live / "state.pt").read_bytes() == b"x"
    finally:
        os.close(fd)
    remove_idle_work(out)  # released: now idle, and .work goes with it
    assert not (out / ".work").exists()
    remove_idle_work(out)  # nothing to do
