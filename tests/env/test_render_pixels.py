"""What a reader of a rendered frame sees, checked on its pixels (tactical/head-on-fixed): the
ownship is marked and identifiable, the legend shows every colour used, the encounter fills the
frame, and the outcome appears once the episode has ended."""

from __future__ import annotations

import math

import numpy as np
import pytest

import cdr_bench
from cdr_bench import render
from cdr_bench.actions import HOLD
from cdr_bench.sim import OUTCOME_NAMES

# A LoS ends head-on-fixed's episode at step 2 when every aircraft holds.
SCENARIO = "tactical/head-on-fixed"


def _mask(frame: np.ndarray, colour: tuple[int, int, int]) -> np.ndarray:
    return np.all(frame == np.asarray(colour, dtype=np.uint8), axis=-1)


def _crop(frame: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    x0, y0, x1, y1 = box
    return frame[y0:y1, x0:x1]


@pytest.fixture(scope="module")
def episode():
    env = cdr_bench.parallel_env(SCENARIO, render_mode="rgb_array")
    env.reset(seed=0)
    sim = env.sim
    start = {
        "frame": env.render(),
        "view": render.frame_view(sim),
        "own": sim.ac_pos_km[0, 0].copy(),
        "own_level": int(sim.ac_level[0, 0]),
        "bg": [
            (sim.bg_pos_km[0, b].copy(), int(sim.bg_level[0, b]))
            for b in np.flatnonzero(sim.bg_active[0])
        ],
    }
    infos: dict = {}
    for _ in range(10):
        if not env.agents:
            break
        _, _, _, _, infos = env.step({a: HOLD for a in env.agents})
    assert not env.agents, "head-on with every aircraft holding should end within 10 steps"
    end = {"frame": env.render(), "outcome": infos["ownship_0"]["outcome"]}
    yield env, start, end
    env.close()


def test_frame_is_stable_and_not_blank(episode):
    _, start, end = episode
    for f in (start["frame"], end["frame"]):
        assert f.shape == (render.SIZE_PX, render.SIZE_PX, 3) and f.dtype == np.uint8
        packed = f.reshape(-1, 3).astype(np.uint32) @ np.array([1 << 16, 1 << 8, 1], np.uint32)
        assert len(np.unique(packed)) > 20
        m = _crop(f, render.MAP_BOX)
        drawn = np.any(m != np.asarray(render.BACKGROUND, dtype=np.uint8), axis=-1)
        assert drawn.mean() > 0.01, "the map is (nearly) empty"


def test_ownship_marker_is_drawn_and_unique(episode):
    _, start, _ = episode
    f, view = start["frame"], start["view"]
    x, y = (int(round(c)) for c in view.px(start["own"]))
    assert render.MAP_BOX[0] <= x < render.MAP_BOX[2] and render.MAP_BOX[1] <= y < render.MAP_BOX[3]
    # Filled with the colour of its level, outlined with the ownship colour ...
    assert tuple(f[y, x]) == render.LEVEL_COLOURS[start["own_level"]]
    box = (x - 16, y - 16, x + 17, y + 17)
    assert _mask(_crop(f, box), render.OWNSHIP_OUTLINE).sum() >= 20
    # ... which appears nowhere else on the map.
    outline = _mask(_crop(f, render.MAP_BOX), render.OWNSHIP_OUTLINE)
    oy, ox = y - render.MAP_BOX[1], x - render.MAP_BOX[0]
    outline[max(oy - 16, 0) : oy + 17, max(ox - 16, 0) : ox + 17] = False
    assert outline.sum() == 0


def test_legend_shows_every_colour(episode):
    _, start, _ = episode
    legend = _crop(start["frame"], render.LEGEND_BOX)
    colours = [*render.LEVEL_COLOURS, render.OWNSHIP_OUTLINE, render.GOAL, render.ALARM]
    for colour in colours:
        assert _mask(legend, colour).sum() >= 10, f"legend lacks colour {colour}"


def test_encounter_fills_the_frame(episode):
    _, start, _ = episode
    f, view = start["frame"], start["view"]
    # Every background aircraft is drawn inside the map, filled with its level's colour.
    assert len(start["bg"]) == 4
    for pos, level in start["bg"]:
        x, y = (int(round(c)) for c in view.px(pos))
        assert render.MAP_BOX[0] <= x < render.MAP_BOX[2]
        assert render.MAP_BOX[1] <= y < render.MAP_BOX[3]
        assert tuple(f[y, x]) == render.LEVEL_COLOURS[level]
    # The aircraft-coloured pixels of the map span a good share of the frame.
    m = _crop(f, render.MAP_BOX)
    aircraft = np.zeros(m.shape[:2], dtype=bool)
    for colour in render.LEVEL_COLOURS:
        aircraft |= _mask(m, colour)
    ys, xs = np.nonzero(aircraft)
    width = (xs.max() - xs.min() + 1) / f.shape[1]
    height = (ys.max() - ys.min() + 1) / f.shape[0]
    assert max(width, height) >= 0.3, (width, height)
    assert min(width, height) >= 0.2, (width, height)


def test_outcome_appears_when_the_episode_ends(episode):
    _, start, end = episode
    assert end["outcome"] == "los"
    code = next(c for c, name in OUTCOME_NAMES.items() if name == end["outcome"])
    chip = render.OUTCOME_COLOURS[code]
    before = _crop(start["frame"], render.STATUS_BOX)
    after = _crop(end["frame"], render.STATUS_BOX)
    assert _mask(before, chip).sum() == 0
    assert _mask(after, chip).sum() > 300
    assert np.any(before != after, axis=-1).mean() > 0.05


def test_zoom_option(episode):
    env, _, _ = episode
    sim = env.sim
    whole = render.frame_view(sim, zoom_km=math.inf)
    close = render.frame_view(sim, zoom_km=20.0)
    assert not whole.zoomed and close.zoomed
    assert close.px_per_km > 5 * whole.px_per_km
    # The ownship is the centre of an explicit zoom window.
    cx = (render.MAP_BOX[0] + render.MAP_BOX[2]) / 2
    cy = (render.MAP_BOX[1] + render.MAP_BOX[3]) / 2
    assert close.px(sim.ac_pos_km[0, 0]) == pytest.approx((cx, cy))
    f = render.draw_frame(sim, zoom_km=math.inf)
    assert f.shape == (render.SIZE_PX, render.SIZE_PX, 3) and f.dtype == np.uint8
    for bad in (0.0, -5.0, float("nan")):
        with pytest.raises(ValueError, match="zoom_km"):
            render.frame_view(sim, zoom_km=bad)


def test_whole_sector_without_an_explicit_encounter():
    env = cdr_bench.parallel_env("low", render_mode="rgb_array")
    env.reset(seed=1)
    view = render.frame_view(env.sim)
    assert not view.zoomed
    assert render.encounter_box(env.config) is None
    assert render.encounter_box(cdr_bench.parallel_env(SCENARIO).config) is not None
    frame = env.render()
    assert frame.shape == (render.SIZE_PX, render.SIZE_PX, 3)


def test_a_drawn_encounter_is_in_view():
    """A family draws its aircraft per episode: the view fits every start it can draw."""
    env = cdr_bench.parallel_env("tactical/head-on", render_mode="rgb_array")
    for seed in range(5):
        env.reset(seed=seed)
        view = render.frame_view(env.sim)
        assert view.zoomed
        for pos in env.sim.bg_pos_km[0]:
            x, y = view.px(pos)
            assert render.MAP_BOX[0] <= x < render.MAP_BOX[2]
            assert render.MAP_BOX[1] <= y < render.MAP_BOX[3]


def test_env_render_zoom_attribute():
    env = cdr_bench.parallel_env("tactical/head-on", render_mode="rgb_array")
    env.reset(seed=0)
    auto = env.render()
    env.render_zoom_km = math.inf
    whole = env.render()
    env.render_zoom_km = None
    assert np.array_equal(env.render(), auto)
    assert not np.array_equal(whole, auto)
