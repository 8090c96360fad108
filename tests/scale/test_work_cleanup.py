"""The end of a sweep removes only idle work folders with nothing to continue: two sweep
processes on one output folder (one per core) must not delete each other's running attempts
(before this, the first sweep to finish removed the whole ``.work`` folder and a running
Diffusion-AC seed with it), and a dead attempt's saved state stays for ``--resume``."""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from cdr_bench.scale.sweep import remove_idle_work


def test_live_attempts_survive_and_idle_ones_go(tmp_path: Path) -> None:
    out = tmp_path / "out"
    idle, live = (out / ".work" / n for n in ("k1-idle", "k3-live"))
    for d in (idle, live):
        d.mkdir(parents=True)
        (d / "args.json").write_text("{}")  # started, nothing saved yet: nothing to continue
    (live / ".lock").write_text("")
    fd = os.open(live / ".lock", os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX)  # the running attempt of another sweep process
    try:
        assert remove_idle_work(out) == []
        assert not idle.exists()
        assert (live / "args.json").is_file()
    finally:
        os.close(fd)
    remove_idle_work(out)  # released: now idle, and .work goes with it
    assert not (out / ".work").exists()
    remove_idle_work(out)  # nothing to do


def test_a_dead_attempts_saved_state_is_kept_for_resume(tmp_path: Path) -> None:
    """A raylet killed under a running trial fails the sweep; the attempt's saved state is what
    ``--resume`` continues, so the end of that sweep must keep it (it deleted an hour of a
    Table 3 trial). Kept: saved state or finished training of a trial that has not landed.
    Removed: the leftovers of a trial that landed (another attempt won)."""
    out = tmp_path / "out"
    dead, trained, stale = (out / ".work" / n for n in ("k2-dead0001", "k4-done0001", "k5-old0001"))
    for d in (dead, trained, stale):
        d.mkdir(parents=True)
        (d / ".lock").write_text("")  # a lock file nobody holds: its attempt died
    (dead / "state.pt").write_bytes(b"x")
    (trained / "train.done").write_text("")
    (stale / "state.pt").write_bytes(b"y")
    (out / "k5").mkdir()
    (out / "k5" / "trial.json").write_text("{}")  # k5 landed from another attempt
    assert remove_idle_work(out) == [dead, trained]
    assert (dead / "state.pt").read_bytes() == b"x" and (trained / "train.done").is_file()
    assert not stale.exists()
