"""Top-down picture of the sector (Pillow): one 512 x 512 RGB frame. No simulator state is
changed here.

Layout: a header (scenario, step and time, then the status or outcome of every controlled
aircraft), the map, and a legend strip. On the map the **shape** tells the role (ownship: a
triangle with a black outline, pointing along its heading; learning intruder: a diamond;
background traffic: a circle) and the **fill colour** the flight level (Okabe-Ito palette,
colour-blind safe; labels repeat the level when few aircraft are in view). The line ahead of an
aircraft is its heading (when zoomed in: the distance it flies in one step). The thin ring
around the ownship (and learning intruders) is the LoS zone of radius ``separation.los_km``
(only aircraft at the same level count); a vermilion ring marks an aircraft that lost
separation during the last step. The ownship's goal is a purple cross with its goal radius, or an
arrow at the map edge with its distance when outside the view. A scale bar sits bottom left.

Zoom (:func:`frame_view`): an explicit encounter (the scenario places the ownship and background
aircraft, as the tactical scenarios do) is shown close up: the view fits the ownship, the
aircraft within :data:`ENCOUNTER_RADIUS_KM` of it at the start (for an aircraft placed by an
encounter, the square its start can be drawn in) and its goal when near, and then
follows the ownship at that fixed scale. Anything else shows the whole sector, unless
``zoom_km`` asks for a window of that half-width around the ownship (``math.inf``: the whole
sector, also for an encounter).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw, ImageFont

from cdr_bench.scenarios.schema import ScenarioConfig, encounter_reach_km
from cdr_bench.sim.core import BOUNDARY, LOS, NMAC, SUCCESS, TIMEOUT, Simulator, StepResult
from cdr_bench.sim.units import KM_PER_S_PER_KT

Colour = tuple[int, int, int]
Box = tuple[int, int, int, int]
"""x0, y0, x1, y1 in frame pixels (x1 and y1 exclusive)."""

SIZE_PX = 512
HEADER_PX = 40
LEGEND_PX = 50
HEADER_BOX: Box = (0, 0, SIZE_PX, HEADER_PX)
STATUS_BOX: Box = (0, 20, SIZE_PX, HEADER_PX)
"""Second header line: status or outcome of every controlled aircraft."""
MAP_BOX: Box = (0, HEADER_PX, SIZE_PX, SIZE_PX - LEGEND_PX)
LEGEND_BOX: Box = (0, SIZE_PX - LEGEND_PX, SIZE_PX, SIZE_PX)
SECTOR_MARGIN_PX = 14

# Okabe-Ito colours (distinguishable with the common colour-vision deficiencies).
LEVEL_COLOURS: list[Colour] = [(0, 114, 178), (0, 158, 115), (230, 159, 0)]  # FL0 FL1 FL2
"""Fill colour of an aircraft by flight level index."""
OWNSHIP_OUTLINE: Colour = (0, 0, 0)
"""Outline of the ownship marker (used nowhere else)."""
INTRUDER_OUTLINE: Colour = (60, 60, 60)
ALARM: Colour = (213, 94, 0)
"""Ring of an aircraft in LoS, failure outcomes."""
GOAL: Colour = (204, 121, 167)
OUTCOME_COLOURS: dict[int, Colour] = {
    SUCCESS: (0, 110, 80),
    NMAC: ALARM,
    LOS: ALARM,
    BOUNDARY: ALARM,
    TIMEOUT: (100, 100, 100),
}
BACKGROUND: Colour = (250, 250, 247)
PANEL: Colour = (236, 236, 231)
TEXT: Colour = (30, 30, 30)
MUTED: Colour = (95, 95, 95)
NEUTRAL: Colour = (175, 175, 175)
TRACK: Colour = (120, 120, 120)
ZONE: Colour = (125, 125, 125)
AIRWAY: Colour = (214, 214, 208)
SECTOR_EDGE: Colour = (60, 60, 60)

OWNSHIP_R_PX = 9.0
INTRUDER_R_PX = 7.0
BACKGROUND_R_PX = 5.5
TICK_PX = 14.0
"""Heading line of the whole-sector view (too small to draw one step to scale)."""
LABEL_LIMIT = 12
"""Aircraft get text labels when at most this many are in view."""
ENCOUNTER_RADIUS_KM = 100.0
"""Explicit aircraft this close to the ownship's start are part of its encounter."""

OUTCOME_TEXT = {
    SUCCESS: "SUCCESS, goal reached",
    LOS: "LoS, loss of separation",
    NMAC: "NMAC, near mid-air collision",
    BOUNDARY: "left the sector",
    TIMEOUT: "TIMEOUT, step limit reached",
}
OUTCOME_SHORT = {
    SUCCESS: "success",
    LOS: "LoS",
    NMAC: "NMAC",
    BOUNDARY: "left",
    TIMEOUT: "timeout",
}


@functools.cache
def _font(size: int) -> Any:
    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError, AttributeError):  # Pillow < 10.1 or no FreeType: bitmap font
        return ImageFont.load_default()


@dataclass(frozen=True)
class View:
    """The map projection: world km to frame pixels, north up, one scale on both axes."""

    centre_km: tuple[float, float]
    px_per_km: float
    zoomed: bool

    def px(self, p: Any) -> tuple[float, float]:
        x0, y0, x1, y1 = MAP_BOX
        return (
            (x0 + x1) / 2 + (float(p[0]) - self.centre_km[0]) * self.px_per_km,
            (y0 + y1) / 2 - (float(p[1]) - self.centre_km[1]) * self.px_per_km,
        )


def encounter_box(config: ScenarioConfig) -> tuple[float, float, float, float] | None:
    """The extent (x0, y0, x1, y1), km relative to the ownship's start, of an explicit encounter:
    the ownship, the placed aircraft within :data:`ENCOUNTER_RADIUS_KM` of it, its goal when
    within 1.5 times the farthest of them, and a margin. None when the scenario does not place
    both the ownship and some aircraft near it."""
    start = config.ownship.start
    if start is None or not config.aircraft:
        return None
    ox, oy = start.position_km
    near = []
    for a in config.aircraft:
        if a.encounter is not None:  # drawn per episode: the square its start can be in
            r = encounter_reach_km(config, a.encounter)
            near += [(-r, -r), (r, r)]
        elif a.position_km is not None:
            x, y = a.position_km[0] - ox, a.position_km[1] - oy
            if math.hypot(x, y) <= ENCOUNTER_RADIUS_KM:
                near.append((x, y))
    if not near:
        return None
    reach = max(math.hypot(x, y) for x, y in near)
    points = [(0.0, 0.0), *near]
    goal = config.ownship.goal_km
    if goal is not None and math.hypot(goal[0] - ox, goal[1] - oy) <= 1.5 * reach:
        points.append((goal[0] - ox, goal[1] - oy))
    margin = max(config.separation.los_km, 0.1 * reach, 2.0)
    xs = [p[0] for p in points]
    ys = [p[1] for p in points]
    return (min(xs) - margin, min(ys) - margin, max(xs) + margin, max(ys) + margin)


def frame_view(sim: Simulator, episode: int = 0, zoom_km: float | None = None) -> View:
    """The view of a frame of episode ``episode`` (see the module docstring).

    ``zoom_km``: None chooses (an explicit encounter close up, else the whole sector); a
    positive number shows that many km around the ownship (half the shorter side of the map);
    ``math.inf`` the whole sector."""
    w, h = MAP_BOX[2] - MAP_BOX[0], MAP_BOX[3] - MAP_BOX[1]
    own = sim.ac_pos_km[episode, 0]
    size = sim.size_km
    whole = View((size / 2, size / 2), (min(w, h) - 2 * SECTOR_MARGIN_PX) / size, False)
    if zoom_km is not None:
        z = float(zoom_km)
        if not z > 0:
            raise ValueError(f"zoom_km must be a positive number of km or math.inf, got {zoom_km}")
        if math.isinf(z):
            return whole
        return View((float(own[0]), float(own[1])), min(w, h) / (2 * z), True)
    box = encounter_box(sim.config)
    if box is None:
        return whole
    x0, y0, x1, y1 = box
    scale = min(w / (x1 - x0), h / (y1 - y0))
    centre = (float(own[0]) + (x0 + x1) / 2, float(own[1]) + (y0 + y1) / 2)
    return View(centre, scale, True)


def draw_frame(
    sim: Simulator,
    trail: Sequence[Sequence[float]] | None = None,
    last: StepResult | None = None,
    episode: int = 0,
    *,
    zoom_km: float | None = None,
) -> NDArray[np.uint8]:
    """RGB frame (512, 512, 3) uint8 of episode ``episode`` of ``sim``: ``trail`` is the
    ownship's track so far, ``last`` the result of the last step (LoS rings), ``zoom_km`` as in
    :func:`frame_view`."""
    view = frame_view(sim, episode, zoom_km)
    img = Image.new("RGB", (SIZE_PX, SIZE_PX), BACKGROUND)
    d = ImageDraw.Draw(img)
    _draw_map(d, sim, view, trail, last, episode)
    # The panels are drawn after the map and cover whatever of it lies outside the map box.
    _draw_header(d, sim, episode)
    _draw_legend(d, sim)
    return np.asarray(img, dtype=np.uint8)


# -- map ---------------------------------------------------------------------------------------


def _draw_map(
    d: ImageDraw.ImageDraw,
    sim: Simulator,
    view: View,
    trail: Sequence[Sequence[float]] | None,
    last: StepResult | None,
    e: int,
) -> None:
    px = view.px
    k = view.px_per_km
    size = sim.size_km
    cfg = sim.config
    for w in cfg.airways[: sim.R]:
        d.line([px(w.start_km), px(w.end_km)], fill=AIRWAY, width=2 if view.zoomed else 1)
    x0, y0 = px((0.0, size))
    x1, y1 = px((size, 0.0))
    d.rectangle([x0, y0, x1, y1], outline=SECTOR_EDGE, width=2)

    alarm = np.zeros(sim.N, dtype=bool)
    if last is not None:
        los = np.asarray(last.los_with[e])  # (M, N): controlled m in LoS with aircraft n
        alarm |= los.any(axis=0)
        alarm[sim.B :] |= los.any(axis=1)

    if trail is not None and len(trail) > 1:
        d.line([px(p) for p in trail], fill=TRACK, width=2, joint="curve")

    # LoS zones of the controlled aircraft, under everything else.
    los_px = sim.los_km * k
    for m in range(sim.M):
        if m == 0 or sim.ac_active[e, m]:
            x, y = px(sim.ac_pos_km[e, m])
            red = bool(alarm[sim.B + m])
            d.ellipse(
                [x - los_px, y - los_px, x + los_px, y + los_px],
                outline=ALARM if red else ZONE,
                width=2 if red or m == 0 else 1,
            )

    tags = _Labels(d)
    # Goals: the ownship's (purple, with its radius) and the learning intruders' (grey).
    for m in range(sim.M - 1, -1, -1):
        if m and not sim.ac_active[e, m]:
            continue
        _goal(d, view, sim.ac_pos_km[e, m], sim.ac_goal_km[e, m], cfg, m == 0, tags)

    inside = _inside_map
    bgs = [int(b) for b in np.flatnonzero(sim.bg_active[e])]
    ctrl = [m for m in range(sim.M) if m == 0 or sim.ac_active[e, m]]
    n_visible = sum(inside(px(sim.bg_pos_km[e, b])) for b in bgs) + sum(
        inside(px(sim.ac_pos_km[e, m])) for m in ctrl
    )
    labels = n_visible <= LABEL_LIMIT

    def vector(x: float, y: float, ux: float, uy: float, km: float, start: float, col: Colour):
        """Heading line from ``start`` px ahead of (x, y) along screen direction (ux, uy)."""
        n = math.hypot(ux, uy)
        if n == 0:
            return
        ux, uy = ux / n, uy / n
        length = km * k if view.zoomed else TICK_PX
        if length <= start:
            length = start + 4
        end = (x + ux * length, y + uy * length)
        d.line([(x + ux * start, y + uy * start), end], fill=col, width=2)

    step_s = sim.dt_s
    for b in bgs:
        x, y = px(sim.bg_pos_km[e, b])
        if not _near_map((x, y)):
            continue
        lvl = int(sim.bg_level[e, b])
        col = LEVEL_COLOURS[lvl]
        v = sim.bg_vel_km_s[e, b]
        vector(x, y, v[0], -v[1], math.hypot(v[0], v[1]) * step_s, BACKGROUND_R_PX, col)
        r = BACKGROUND_R_PX
        d.ellipse([x - r, y - r, x + r, y + r], fill=col)
        if alarm[b]:
            _alarm_ring(d, x, y, r)
        tags.obstacle(x, y, r)
        if labels and inside((x, y)):
            tags.tag(x, y, r, v[0], -v[1], f"FL{lvl}")

    for m in sorted(ctrl, reverse=True):  # the ownship last, on top
        x, y = px(sim.ac_pos_km[e, m])
        lvl = int(sim.ac_level[e, m])
        col = LEVEL_COLOURS[lvl]
        ux, uy = float(sim.ac_dir[e, m, 0]), -float(sim.ac_dir[e, m, 1])
        if sim.ac_active[e, m]:
            km = float(sim.ac_speed_kt[e, m]) * KM_PER_S_PER_KT * step_s
            r0 = OWNSHIP_R_PX * 1.4 if m == 0 else INTRUDER_R_PX
            vector(x, y, ux, uy, km, r0, col)
        if m == 0:
            _ownship(d, x, y, ux, uy, OWNSHIP_R_PX, col)
            r = OWNSHIP_R_PX
        else:
            _diamond(d, x, y, INTRUDER_R_PX, col, INTRUDER_OUTLINE)
            r = INTRUDER_R_PX
        if alarm[sim.B + m]:
            _alarm_ring(d, x, y, r + 2)
        tags.obstacle(x, y, r)
        if labels or m == 0:
            name = "own" if m == 0 else f"int{m - 1}"
            code = int(sim.ac_outcome[e, m])
            text = f"{name} FL{lvl}" + (f": {OUTCOME_SHORT[code]}" if code in OUTCOME_SHORT else "")
            tags.tag(x, y, r, ux, uy, text)
    tags.queue.reverse()  # the ownship's label first
    tags.flush()
    _scale_bar(d, view)


def _inside_map(p: tuple[float, float], pad: float = 0.0) -> bool:
    x0, y0, x1, y1 = MAP_BOX
    return x0 + pad <= p[0] <= x1 - pad and y0 + pad <= p[1] <= y1 - pad


def _near_map(p: tuple[float, float]) -> bool:
    return _inside_map(p, -60.0)


def _label(d: ImageDraw.ImageDraw, x: float, y: float, text: str, font: Any) -> None:
    d.text((x, y), text, fill=TEXT, font=font, stroke_width=2, stroke_fill=BACKGROUND)


class _Labels:
    """Text labels of the map, placed last: each beside its marker, in the first corner (away
    from the marker's heading first) that overlaps neither a marker nor an earlier label."""

    def __init__(self, d: ImageDraw.ImageDraw):
        self.d = d
        self.font = _font(11)
        self.taken: list[tuple[float, float, float, float]] = []
        self.queue: list[tuple[float, float, float, float, float, str]] = []
        self.fixed: list[tuple[float, float, str]] = []

    def obstacle(self, x: float, y: float, r: float) -> None:
        self.taken.append((x - r, y - r, x + r, y + r))

    def tag(self, x: float, y: float, r: float, ux: float, uy: float, text: str) -> None:
        self.queue.append((x, y, r, ux, uy, text))

    def at(self, x: float, y: float, text: str) -> None:
        """A label at a fixed place (top left corner), placed before the others."""
        self.fixed.append((x, y, text))

    def put(self, x: float, y: float, text: str) -> None:
        w = self.d.textlength(text, font=self.font)
        self.taken.append((x, y + 2, x + w, y + 13))
        _label(self.d, x, y, text, self.font)

    def _free(self, box: tuple[float, float, float, float]) -> bool:
        x0, y0, x1, y1 = box
        return all(x1 <= a0 or a1 <= x0 or y1 <= b0 or b1 <= y0 for a0, b0, a1, b1 in self.taken)

    def flush(self) -> None:
        for fx, fy, text in self.fixed:
            self.put(fx, fy, text)
        corners = [(1, -1), (1, 1), (-1, -1), (-1, 1)]  # right-up, right-down, left-up, left-down
        for x, y, r, ux, uy, text in self.queue:
            w = self.d.textlength(text, font=self.font)
            spots = []
            for sx, sy in sorted(corners, key=lambda c: c[0] * ux + c[1] * uy):
                tx = x + r + 2 if sx > 0 else x - r - 2 - w
                ty = y - r - 11 if sy < 0 else y + r - 3
                spots.append((tx, ty))
            spots += [(x - w / 2, y - r - 15), (x - w / 2, y + r + 1)]  # above, below
            tx, ty = next(
                (p for p in spots if self._free((p[0], p[1] + 2, p[0] + w, p[1] + 13))), spots[0]
            )
            self.put(tx, ty, text)
        self.queue.clear()
        self.fixed.clear()


def _alarm_ring(d: ImageDraw.ImageDraw, x: float, y: float, r: float) -> None:
    r += 4
    d.ellipse([x - r, y - r, x + r, y + r], outline=ALARM, width=3)


def _ownship(
    d: ImageDraw.ImageDraw, x: float, y: float, ux: float, uy: float, r: float, fill: Colour
) -> None:
    """Triangle pointing along the screen direction (ux, uy), centred near (x, y)."""
    n = math.hypot(ux, uy)
    ux, uy = (ux / n, uy / n) if n > 0 else (0.0, -1.0)
    nx, ny = -uy, ux
    pts = [
        (x + ux * r * 1.4, y + uy * r * 1.4),
        (x - ux * r * 0.9 + nx * r, y - uy * r * 0.9 + ny * r),
        (x - ux * r * 0.9 - nx * r, y - uy * r * 0.9 - ny * r),
    ]
    d.polygon(pts, fill=fill, outline=OWNSHIP_OUTLINE, width=2)


def _diamond(
    d: ImageDraw.ImageDraw, x: float, y: float, r: float, fill: Colour, outline: Colour
) -> None:
    d.polygon([(x, y - r), (x + r, y), (x, y + r), (x - r, y)], fill=fill, outline=outline, width=1)


def _cross(d: ImageDraw.ImageDraw, x: float, y: float, r: float, col: Colour) -> None:
    d.line([x - r, y - r, x + r, y + r], fill=col, width=3)
    d.line([x - r, y + r, x + r, y - r], fill=col, width=3)


def _goal(
    d: ImageDraw.ImageDraw,
    view: View,
    pos: Any,
    goal: Any,
    cfg: ScenarioConfig,
    own: bool,
    tags: _Labels,
) -> None:
    gx, gy = view.px(goal)
    col = GOAL if own else NEUTRAL
    if _inside_map((gx, gy), 8.0):
        rr = cfg.ownship.goal_radius_km * view.px_per_km
        if own and rr > 8:
            d.ellipse([gx - rr, gy - rr, gx + rr, gy + rr], outline=GOAL, width=1)
        _cross(d, gx, gy, 6.0 if own else 4.5, col)
        tags.obstacle(gx, gy, 6.0)
        if own:
            tags.tag(gx, gy, 6.0, 0.0, 0.0, "goal")
        return
    if not own:
        return
    # Outside the view: an arrow on the map edge, on the line from the ownship to the goal.
    ox, oy = view.px(pos)
    x0, y0, x1, y1 = MAP_BOX
    pad = 14.0
    lo_x, lo_y, hi_x, hi_y = x0 + pad, y0 + pad, x1 - pad, y1 - pad
    dx, dy = gx - ox, gy - oy
    n = math.hypot(dx, dy)
    if n == 0:
        return
    ux, uy = dx / n, dy / n
    if _inside_map((ox, oy), pad):
        t = min(
            ((hi_x - ox) / ux if ux > 0 else (lo_x - ox) / ux) if ux else math.inf,
            ((hi_y - oy) / uy if uy > 0 else (lo_y - oy) / uy) if uy else math.inf,
        )
        ax, ay = ox + ux * t, oy + uy * t
    else:
        ax, ay = min(max(gx, lo_x), hi_x), min(max(gy, lo_y), hi_y)
    s = 9.0
    nx, ny = -uy, ux
    d.polygon(
        [
            (ax + ux * s, ay + uy * s),
            (ax - ux * s + nx * s * 0.8, ay - uy * s + ny * s * 0.8),
            (ax - ux * s - nx * s * 0.8, ay - uy * s - ny * s * 0.8),
        ],
        fill=GOAL,
    )
    km = math.hypot(float(goal[0]) - float(pos[0]), float(goal[1]) - float(pos[1]))
    text = f"goal {km:.0f} km"
    tw = d.textlength(text, font=_font(11))
    tags.obstacle(ax, ay, s)
    # Beside the arrow, inward: below it unless it points down.
    tx = min(max(ax - tw / 2 - ux * tw / 2, x0 + 4), x1 - tw - 4)
    ty = min(max(ay + 10 if uy < 0.5 else ay - 26, y0 + 4), y1 - 16)
    tags.at(tx, ty, text)


def _nice_km(target: float) -> float:
    """The largest 1, 2 or 5 times a power of ten not above ``target``."""
    p = 10.0 ** math.floor(math.log10(target))
    for m in (5.0, 2.0, 1.0):
        if m * p <= target:
            return m * p
    return p


def _scale_bar(d: ImageDraw.ImageDraw, view: View) -> None:
    x0, _, x1, y1 = MAP_BOX
    km = _nice_km(0.22 * (x1 - x0) / view.px_per_km)
    length = km * view.px_per_km
    bx, by = x0 + 12, y1 - 10
    d.rectangle([bx - 4, by - 20, bx + length + 4, by + 5], fill=BACKGROUND)
    d.line([bx, by, bx + length, by], fill=TEXT, width=2)
    for t in (bx, bx + length):
        d.line([t, by - 5, t, by], fill=TEXT, width=2)
    d.text((bx, by - 19), f"{km:g} km  (north up)", fill=TEXT, font=_font(11))


# -- header and legend -------------------------------------------------------------------------


def _draw_header(d: ImageDraw.ImageDraw, sim: Simulator, e: int) -> None:
    x0, y0, x1, y1 = HEADER_BOX
    d.rectangle([x0, y0, x1 - 1, y1 - 1], fill=PANEL)
    d.line([x0, y1 - 1, x1, y1 - 1], fill=NEUTRAL, width=1)
    title = _font(13)
    d.text((8, 3), sim.config.id or "(unnamed scenario)", fill=TEXT, font=title)
    step = int(sim.steps[e])
    seconds = int(round(step * sim.dt_s))
    clock = f"step {step}/{sim.max_steps}   t = {seconds // 60} min {seconds % 60:02d} s"
    d.text((x1 - 8 - d.textlength(clock, font=title), 3), clock, fill=TEXT, font=title)

    font = _font(12)
    x = 8.0
    y = STATUS_BOX[1] + 1
    single = sim.M == 1
    for m in range(sim.M):
        code = int(sim.ac_outcome[e, m])
        name = ("ownship" if single else "own") if m == 0 else f"int{m - 1}"
        if code in OUTCOME_TEXT:
            text = f"{name}: {OUTCOME_TEXT[code] if single else OUTCOME_SHORT[code]}"
        else:
            text = f"{name} FL{int(sim.ac_level[e, m])}: flying"
            if single:
                g = sim.ac_goal_km[e, m] - sim.ac_pos_km[e, m]
                text += f", goal {math.hypot(g[0], g[1]):.0f} km"
        w = d.textlength(text, font=font)
        if x + w + 12 > x1 - 8:
            d.text((x, y), "...", fill=MUTED, font=font)
            break
        if code in OUTCOME_TEXT:
            d.rounded_rectangle(
                [x - 4, y - 1, x + w + 4, y + 15], radius=4, fill=OUTCOME_COLOURS[code]
            )
            d.text((x, y), text, fill=(255, 255, 255), font=font)
        else:
            d.text((x, y), text, fill=MUTED, font=font)
        x += w + 16


def _draw_legend(d: ImageDraw.ImageDraw, sim: Simulator) -> None:
    x0, y0, x1, y1 = LEGEND_BOX
    d.rectangle([x0, y0, x1 - 1, y1 - 1], fill=PANEL)
    d.line([x0, y0, x1, y0], fill=NEUTRAL, width=1)
    font = _font(11)
    gap = 14.0

    def item(x: float, y: float, text: str) -> float:
        d.text((x, y - 7), text, fill=TEXT, font=font)
        return x + d.textlength(text, font=font) + gap

    # Row 1: shape = role.
    y = y0 + 14.0
    x = 10.0
    x = item(x, y, "shape:") - gap + 12
    _ownship(d, x + 4, y, 0.0, -1.0, 6.0, NEUTRAL)
    x = item(x + 16, y, "ownship")
    _diamond(d, x + 6, y, 6.0, NEUTRAL, INTRUDER_OUTLINE)
    x = item(x + 16, y, "learning intruder")
    d.ellipse([x + 1, y - 5, x + 11, y + 5], fill=NEUTRAL)
    x = item(x + 16, y, "background traffic")
    _cross(d, x + 6, y, 5.0, GOAL)
    item(x + 16, y, "goal")

    # Row 2: colour = flight level, rings.
    y = y0 + 36.0
    x = 10.0
    x = item(x, y, "colour:") - gap + 12
    for lvl, col in enumerate(LEVEL_COLOURS):
        d.rectangle([x, y - 5, x + 10, y + 5], fill=col)
        x = item(x + 14, y, f"FL{lvl}") - 4
    x += 6
    d.ellipse([x, y - 6, x + 12, y + 6], outline=ZONE, width=2)
    x = item(x + 16, y, f"LoS zone {sim.los_km:g} km (same level)")
    d.ellipse([x, y - 6, x + 12, y + 6], outline=ALARM, width=3)
    item(x + 16, y, "in LoS")


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


def save_gif(frames: list[NDArray[np.uint8]], path: str | IO[bytes], fps: int = 8) -> None:
    """Write frames as an animated GIF to a path or a binary file object."""
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


PNG_COLOURS = 128
"""Colours of a figure's PNG (:func:`figure_png`): a plot's lines, markers, bands and
anti-aliased text fit, at a third of the bytes of full colour."""


def figure_png(fig: Any, dpi: int) -> bytes:
    """The PNG of a matplotlib figure, closed afterwards: no ``Software`` metadata, reduced to
    :data:`PNG_COLOURS` palette colours (median cut, no dithering) and compressed at the
    highest level, so the same figure gives the same bytes with the same matplotlib and
    Pillow. Every plot the package writes goes through here (leaderboard plots, training
    curves, multimodality heat maps, sweep plots)."""
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    finally:
        plt.close(fig)
    return quantize_png(buf.getvalue())


def quantize_png(png: bytes) -> bytes:
    """A PNG reduced to :data:`PNG_COLOURS` palette colours (:func:`figure_png`; also what
    turned the committed plots of training runs into the same form)."""
    import io

    img = Image.open(io.BytesIO(png)).convert("RGB")
    palette = img.quantize(PNG_COLOURS, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    out = io.BytesIO()
    palette.save(out, format="PNG", optimize=True)
    return out.getvalue()
