"""Top-down picture of the sector (Pillow): airways, aircraft coloured by level with heading
ticks, LoS rings, the ownship's goal and trail. No simulator state is changed here."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw

from cdr_bench.sim.core import Simulator, StepResult

LEVEL_COLOURS = [(66, 133, 244), (52, 168, 83), (251, 140, 0)]  # level 0, 1, 2
SIZE_PX = 512
MARGIN_PX = 24


def draw_frame(
    sim: Simulator,
    trail: Sequence[Sequence[float]] | None = None,
    last: StepResult | None = None,
    episode: int = 0,
) -> NDArray[np.uint8]:
    """RGB frame (H, W, 3) uint8 of episode ``episode`` of ``sim``."""
    size = sim.size_km
    scale = (SIZE_PX - 2 * MARGIN_PX) / size

    def px(p: Any) -> tuple[float, float]:
        return (MARGIN_PX + float(p[0]) * scale, SIZE_PX - MARGIN_PX - float(p[1]) * scale)

    img = Image.new("RGB", (SIZE_PX, SIZE_PX), (250, 250, 247))
    d = ImageDraw.Draw(img)
    d.rectangle([px((0, size)), px((size, 0))], outline=(40, 40, 40), width=2)
    for w in sim.config.airways[: sim.R]:
        d.line([px(w.start_km), px(w.end_km)], fill=(200, 200, 200), width=1)
    los_r = sim.los_km * scale
    flagged = set()
    if last is not None:
        flagged = set(np.flatnonzero(last.los_with[episode].any(axis=0)).tolist())

    def aircraft(p: Any, v: Any, level: int, radius: float, ring: bool, red: bool) -> None:
        x, y = px(p)
        col = LEVEL_COLOURS[int(level)]
        if ring:
            d.ellipse(
                [x - los_r / 2, y - los_r / 2, x + los_r / 2, y + los_r / 2],
                outline=(220, 30, 30) if red else (170, 170, 170),
                width=1,
            )
        d.ellipse([x - radius, y - radius, x + radius, y + radius], fill=col)
        n = float(np.hypot(v[0], v[1]))
        if n > 0:
            tick = 14.0
            d.line([x, y, x + v[0] / n * tick, y - v[1] / n * tick], fill=col, width=2)

    for b in np.flatnonzero(sim.bg_active[episode]):
        aircraft(
            sim.bg_pos_km[episode, b],
            sim.bg_vel_km_s[episode, b],
            sim.bg_level[episode, b],
            3.5,
            True,
            b in flagged,
        )
    if trail and len(trail) > 1:
        d.line([px(p) for p in trail], fill=(120, 0, 140), width=2)
    vel = sim.ac_vel_km_s[episode]
    for m in range(sim.M):
        gx, gy = px(sim.ac_goal_km[episode, m])
        col = (120, 0, 140) if m == 0 else (90, 90, 90)
        d.line([gx - 6, gy - 6, gx + 6, gy + 6], fill=col, width=2)
        d.line([gx - 6, gy + 6, gx + 6, gy - 6], fill=col, width=2)
        if sim.ac_active[episode, m] or m == 0:
            red = last is not None and bool(last.los_with[episode, m].any())
            aircraft(
                sim.ac_pos_km[episode, m],
                vel[m],
                sim.ac_level[episode, m],
                6.0 if m == 0 else 5.0,
                True,
                red,
            )
    d.text(
        (MARGIN_PX, 4),
        f"{sim.config.id}  step {int(sim.steps[episode])}  levels: blue 0, green 1, orange 2",
        fill=(20, 20, 20),
    )
    return np.asarray(img, dtype=np.uint8)


class HumanWindow:
    """Shows frames in a matplotlib window (no window on a headless backend; never raises)."""

    def __init__(self, fps: int = 8):
        import matplotlib.pyplot as plt

        self._plt = plt
        self._pause = 1.0 / fps
        self._fig, self._ax = plt.subplots(figsize=(6, 6))
        self._ax.set_axis_off()
        self._im: Any = None

    def show(self, frame: NDArray[np.uint8]) -> None:
        if self._im is None:
            self._im = self._ax.imshow(frame)
        else:
            self._im.set_data(frame)
        if self._plt.get_backend().lower() != "agg":
            self._plt.pause(self._pause)

    def close(self) -> None:
        self._plt.close(self._fig)


def save_gif(frames: list[NDArray[np.uint8]], path: str, fps: int = 8) -> None:
    """Write frames as an animated GIF."""
    images = [Image.fromarray(f) for f in frames]
    images[0].save(
        path,
        save_all=True,
        append_images=images[1:],
        duration=int(1000 / fps),
        loop=0,
        optimize=False,
        format="GIF",
    )
