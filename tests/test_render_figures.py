"""Movies and figure panels: time text, frame 0, frame size from the domain, readable labels, cell
outlines, one PNG panel style, identity / polarity / orientation colourings and a settable range, and an MP4 that
can be read while it is being written."""
from __future__ import annotations

import time

import matplotlib
import numpy as np
import pytest

from taichimyxo.io.frame import Frame
from taichimyxo.render import (
    PNG_SIZE,
    VideoWriter,
    compute_layout,
    frame_size,
    make_scale,
    render_frame,
    render_trajectory,
    verify_video,
    write_png,
)
from taichimyxo.render.colors import POLARITY_RGB, identity_colors
from taichimyxo.render.raster import (
    LONGEST_TIME,
    TIME_FONT,
    cell_axis_angle_deg,
    get_renderer,
    glyph_width,
    legend_metrics,
    text_extent,
)

TURBO = matplotlib.colormaps["turbo"]
BOX = (20.0, 20.0)
SIZE = (400, 440)
WHITE = np.array([255, 255, 255], np.uint8)
CLI_SIZES = [(1920, 1080), (1280, 720), (960, 540), (640, 480)]   # the default, common, and --preview's cap


def turbo(x) -> np.ndarray:
    return np.asarray(TURBO(x, bytes=True), np.uint8)[..., :3]


def cell(start, end, n=8) -> np.ndarray:
    return np.linspace(np.asarray(start, float), np.asarray(end, float), n)


def frame(cells, speeds=4.0, box=BOX, time_s=600.0, ke=None, meta=None, strain=None) -> Frame:
    pos = np.stack(cells).astype(np.float64)
    spd = np.broadcast_to(np.asarray(speeds, np.float32).reshape(-1, 1), pos.shape[:2]).copy()
    ke = np.ones(len(pos), np.int8) if ke is None else np.asarray(ke, np.int8)
    return Frame(time_s=time_s, step=int(time_s), box=box, width_um=0.5, positions=pos, engine_direction=ke,
                 particle_speed=spd, segment_strain=strain, meta=meta or {})


def at(img, r, xy):
    row, col = r.viewport.to_pixel(np.asarray(xy, float))
    return img[int(row), int(col)]


# ------------------------------------------------------------------------------------------------ frame 0

def test_first_frame_is_coloured_by_the_free_speed():
    cells = [cell((5, 10), (15, 10))]
    r = get_renderer(BOX, SIZE, "speed")
    f0 = frame(cells, 0.0, time_s=0.0)                                  # t = 0: no displacement measured yet
    assert np.array_equal(at(render_frame(f0, size=SIZE), r, (10, 10)), turbo(4.0 / 16.0))     # v_b = 4 µm/min
    # the scene's v_b when the frame carries its scene (frames read from a trajectory do), or the option
    f0.meta = {"cell": {"speed_um_per_min": 6.0}}
    assert np.array_equal(at(render_frame(f0, size=SIZE), r, (10, 10)), turbo(6.0 / 16.0))
    f0.meta = {}
    assert np.array_equal(at(render_frame(f0, size=SIZE, free_speed=8.0), r, (10, 10)), turbo(0.5))
    # switched off: the zeros; and a later frame that really is at rest stays at 0
    assert np.array_equal(at(render_frame(f0, size=SIZE, t0_free_speed=False), r, (10, 10)), turbo(0.0))
    assert np.array_equal(at(render_frame(frame(cells, 0.0, time_s=60.0), size=SIZE), r, (10, 10)), turbo(0.0))
    # a first frame with measured speeds is shown as measured
    assert np.array_equal(at(render_frame(frame(cells, 12.0, time_s=0.0), size=SIZE), r, (10, 10)), turbo(0.75))


# ------------------------------------------------------------------------------------------------ frame size

@pytest.mark.parametrize("size", CLI_SIZES)
def test_square_domain_fills_the_frame_height_and_the_width_follows(size):
    r = get_renderer((100.0, 100.0), size, "speed", title="S3")
    W, H = r.size
    vp = r.viewport
    assert H == size[1] and W < size[0] and W % 2 == 0 and H % 2 == 0
    assert vp.width == vp.height and vp.height > 0.78 * H            # the box is most of the picture
    assert W - vp.width <= 2 * 0.05 * H + 2                            # only the margins beside it
    assert r.viewport.col0 >= 0 and r.viewport.col0 + vp.width <= W


def test_wide_and_tall_domains_and_exact_size():
    r = get_renderer((400.0, 100.0), (1920, 1080), "speed")
    W, H = r.size
    assert W == 1920 and H < 1080 and H % 2 == 0
    assert abs(r.viewport.width / r.viewport.height - 4.0) < 0.02
    r = get_renderer((50.0, 200.0), (1920, 1080), "speed")
    assert r.size[1] == 1080 and r.size[0] < 1080
    r = get_renderer((100.0, 100.0), (1920, 1080), "speed", fit=False)
    assert r.size == (1920, 1080)
    assert frame_size((100.0, 100.0), (1920, 1080)) == get_renderer((100.0, 100.0), (1920, 1080), "speed").size
    # odd requests give even frames; tiny requests still work
    for size in [(321, 241), (128, 96), (64, 64)]:
        for box in [(20.0, 20.0), (400.0, 100.0), (50.0, 200.0)]:
            w, h = frame_size(box, size, title="S1")
            assert w % 2 == 0 and h % 2 == 0 and 16 <= w <= size[0] + 1 and 16 <= h <= size[1] + 1
            img = render_frame(frame([cell((1, 1), (6, 1))], box=box), size=size, title="S1")
            assert img.shape == (h, w, 3)


# ------------------------------------------------------------------------------------------------ labels

def _ink_rows(img, r0, r1, c0, c1):
    region = img[r0:r1, c0:c1].astype(int)
    dark = (region.sum(axis=-1) < 3 * 128)
    rows = np.nonzero(dark.any(axis=1))[0]
    return (rows.max() - rows.min() + 1) if len(rows) else 0


@pytest.mark.parametrize("size", CLI_SIZES)
def test_tick_labels_are_readable_at_every_cli_size(size):
    fr = frame([cell((5, 10), (15, 10))], 4.0, box=(100.0, 100.0))
    r = get_renderer((100.0, 100.0), size, "speed")
    img = render_frame(fr, size=size)
    lay = r.layout
    assert lay.font_px >= 14 and lay.font_px >= 28 * min(size) / 1080 - 1e-9
    # the ink of the last tick label ("16") is about 0.73 of the font size tall (DejaVu digits)
    r0, r1, c0, c1 = lay.colorbar
    f = lay.font_px
    h = _ink_rows(img, r1 + 2, r1 + int(0.45 * f + 1.3 * f), c1 - int(f), c1 + int(f))
    assert h >= 0.65 * f >= 9, (h, f)


@pytest.mark.parametrize("color", ["speed", "strain", "identity", "polarity", "orientation"])
@pytest.mark.parametrize("size", CLI_SIZES + [(1600, 1200)])
@pytest.mark.parametrize("box", [(200.0, 200.0), (60.0, 60.0), (400.0, 100.0)])
def test_legend_time_and_scale_bar_do_not_overlap(color, size, box):
    sc = make_scale(color)
    lay = compute_layout(size, box, True, scale=sc, title="S10")
    W, H = lay.size
    f = lay.font_px
    cb_min, ov_l, ov_r, leg_h, cb_h = legend_metrics(sc, f)
    r0, r1, c0, c1 = lay.colorbar
    legend = (r0, r0 + leg_h, c0 - ov_l, c1 + ov_r)
    tw = len(LONGEST_TIME) * glyph_width(TIME_FONT * f)
    th = 1.25 * TIME_FONT * f
    tr, tc = lay.time_center
    tl = tc - tw / 2 if lay.time_align == "center" else tc
    time_box = (tr - th / 2, tr + th / 2, tl, tl + tw)
    s0, s1, q0, q1 = lay.scalebar
    lw, lh = text_extent(f"{lay.scalebar_um:g} µm", f)
    sbar = (s0 - 0.2 * f - lh, s1, min(q0, (q0 + q1) / 2 - lw / 2), max(q1, (q0 + q1) / 2 + lw / 2))
    boxes = {"legend": legend, "time": time_box, "scale bar": sbar}
    vp = lay.viewport
    for name, (a0, a1, b0, b1) in boxes.items():
        assert a0 >= vp.row0 + vp.height and a1 <= H + 1 and b0 >= -1 and b1 <= W + 1, (name, lay)
    names = list(boxes)
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            a, b = boxes[names[i]], boxes[names[j]]
            overlap = a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]
            assert not overlap, (names[i], names[j], lay)


# ------------------------------------------------------------------------------------------------ outlines

def test_touching_cells_are_separated_by_a_dark_line():
    # two parallel cells 0.4 µm apart (overlapping: W = 0.5 µm), the same speed colour
    a, b = cell((5, 10.0), (15, 10.0)), cell((5, 10.4), (15, 10.4))
    fr = frame([a, b], 8.0)
    r = get_renderer(BOX, SIZE, "speed")
    fill = turbo(0.5).astype(int)
    col = int(r.viewport.to_pixel((10.0, 10.0))[1])
    rows = np.arange(int(r.viewport.to_pixel((10.0, 10.45))[0]), int(r.viewport.to_pixel((10.0, 9.95))[0]) + 1)
    img = render_frame(fr, size=SIZE)
    line = img[rows, col].astype(int)
    assert np.array_equal(at(img, r, (10, 10.0)), turbo(0.5)) and np.array_equal(at(img, r, (10, 10.4)), turbo(0.5))
    assert (line.sum(axis=1) < 0.5 * fill.sum()).any()                 # a dark pixel between the two axes
    # no outline: nothing but the fill colour between the axes
    img0 = render_frame(fr, size=SIZE, outline=0)
    assert (img0[rows, col] == turbo(0.5)).all()
    # the outer rim is darker than the fill, the background beyond it untouched
    edge = img[int(r.viewport.to_pixel((10.0, 9.75))[0]) - 1: int(r.viewport.to_pixel((10.0, 9.6))[0]) + 1, col]
    assert (edge.astype(int).sum(axis=1) < fill.sum()).any()
    assert np.array_equal(at(img, r, (10.0, 9.4)), WHITE)
    # the segments of one cell join without a line (the whole axis has the fill colour)
    for x in np.linspace(5.2, 14.8, 25):
        assert np.array_equal(at(img, r, (x, 10.0)), turbo(0.5)), x


# ------------------------------------------------------------------------------------------------ colourings

def test_identity_colours_are_per_cell_and_stable():
    cells = [cell((2, 3), (8, 3)), cell((2, 9), (8, 9)), cell((12, 15), (18, 15))]
    r = get_renderer(BOX, SIZE, "identity")
    img = render_frame(frame(cells), size=SIZE, color="identity")
    want = identity_colors(np.arange(3))
    for i, c in enumerate(cells):
        assert np.array_equal(at(img, r, c.mean(axis=0)), want[i])
    assert len({tuple(w) for w in want}) == 3
    # the same cell index has the same colour in another frame, wherever the cell is
    moved = [cell((12, 5), (12, 11)), cell((3, 15), (9, 17)), cell((14, 2), (18, 6))]
    img2 = render_frame(frame(moved, time_s=1200.0), size=SIZE, color="identity")
    for i, c in enumerate(moved):
        assert np.array_equal(at(img2, r, c.mean(axis=0)), want[i])
    pal = identity_colors(np.arange(500))
    assert np.array_equal(pal, identity_colors(np.arange(500)))          # deterministic
    assert len({tuple(p) for p in pal[:12]}) == 12
    assert np.all(pal.astype(int).sum(axis=1) < 3 * 245)               # never (near) white on the white background


def test_polarity_colours_follow_the_engine_direction_and_the_legend():
    cells = [cell((2, 3), (8, 3)), cell((2, 9), (8, 9))]
    r = get_renderer(BOX, SIZE, "polarity")
    img = render_frame(frame(cells, ke=[1, -1]), size=SIZE, color="polarity")
    assert np.array_equal(at(img, r, (5, 3)), POLARITY_RGB[1])
    assert np.array_equal(at(img, r, (5, 9)), POLARITY_RGB[-1])
    r0, r1, c0, c1 = r.layout.colorbar                                 # legend: two swatches, +1 then −1
    mid = (r0 + r1) // 2
    assert np.array_equal(img[mid, c0 + 2], POLARITY_RGB[1]) and np.array_equal(img[mid, c1 - 3], POLARITY_RGB[-1])


def test_orientation_is_the_axis_angle_mod_180_on_a_cyclic_map():
    sc = make_scale("orientation")
    ang = cell_axis_angle_deg(np.stack([cell((5, 5), (10, 5)), cell((10, 5), (5, 5)), cell((5, 5), (5, 10)),
                                        cell((5, 5), (5 + 3 ** 0.5, 6)), cell((5, 5), (5 - 3 ** 0.5, 4))]))
    assert np.allclose(ang, [0.0, 0.0, 90.0, 30.0, 30.0])
    assert np.array_equal(sc.rgb([0.0]), sc.rgb([180.0])) and np.array_equal(sc.rgb([10.0]), sc.rgb([190.0]))
    lut = sc.lut.astype(int)
    assert np.abs(lut[0] - lut[-1]).max() <= 12                         # the two ends of the map meet
    assert np.abs(np.diff(lut, axis=0)).max() <= 20                     # smooth (no jump in 1/256 of the circle)
    r = get_renderer(BOX, SIZE, "orientation")
    cells = [cell((2, 3), (8, 3)), cell((12, 2), (12, 8)), cell((3, 12), (9, 18))]
    img = render_frame(frame(cells, ke=[1, -1, 1]), size=SIZE, color="orientation")
    for c, a in zip(cells, [0.0, 90.0, 45.0]):
        assert np.array_equal(at(img, r, c.mean(axis=0)), sc.rgb([a])[0])
    assert not np.array_equal(sc.rgb([0.0]), sc.rgb([90.0]))


def test_colour_range_is_settable_and_checked():
    cells = [cell((5, 10), (15, 10))]
    r = get_renderer(BOX, SIZE, "speed", vmin=2.0, vmax=6.0)
    img = render_frame(frame(cells, 4.0), size=SIZE, vmin=2.0, vmax=6.0)
    assert np.array_equal(at(img, r, (10, 10)), turbo(0.5))
    assert make_scale("speed", vmax=8.0).ticks == (0.0, 2.0, 4.0, 6.0, 8.0)
    st = make_scale("strain", vmin=1e-20, vmax=1e-16)
    assert np.array_equal(st.rgb([1e-18])[0], turbo(0.5))
    assert st.tick_labels[0] == "$10^{-20}$"
    for bad in [dict(color="speed", vmin=5.0, vmax=5.0), dict(color="strain", vmin=0.0),
                dict(color="identity", vmax=3.0), dict(color="orientation", vmin=0.0), dict(color="colour")]:
        with pytest.raises(ValueError):
            make_scale(bad.pop("color"), **bad)


# ------------------------------------------------------------------------------------------------ files

def _moving_frames(n, box=BOX):
    out = []
    for i in range(n):
        out.append(frame([cell((2.0 + 0.25 * i, 5.0), (9.0 + 0.25 * i, 5.0)), cell((16.0, 12.0), (23.0, 15.5))],
                         [2.0 + i % 10, 16.0], box=box, time_s=60.0 * i))
    return out


def test_mp4_is_readable_while_it_is_being_written(tmp_path):
    import imageio
    import imageio_ffmpeg

    path = tmp_path / "live.mp4"
    frames = _moving_frames(30)
    vw = VideoWriter(path, size=(320, 240), fps=10, keyframe_interval=5)
    try:
        for fr in frames:
            vw.append(fr)
        # while the writer is open: wait (not a timing assertion, a generous bound on a busy machine) until ffmpeg
        # has written fragments, then read the partial file as a player would
        n, deadline = 0, time.monotonic() + 900.0
        while time.monotonic() < deadline:
            try:
                n = imageio_ffmpeg.count_frames_and_secs(str(path))[0]
            except (RuntimeError, OSError):
                n = 0
            if n >= 10:
                break
            time.sleep(0.5)
        assert not vw.closed
        assert n >= 10, f"the partial movie shows {n} frames"
        head = path.read_bytes()[:4096]
        assert head[4:8] == b"ftyp" and b"moov" in head[:2048] and b"moof" in head   # header first, fragments
        rd = imageio.get_reader(str(path), "ffmpeg")
        try:
            first = rd.get_data(0)
        finally:
            rd.close()
        assert first.shape == (vw.size[1], vw.size[0], 3)
    finally:
        vw.close()
    assert verify_video(path, 30) == 30


def test_scene_panel_and_render_panel_are_the_same(tmp_path):
    """run.py writes NAME.png with write_png(last frame, title=name); `render` writes the last frame of the
    trajectory with write_png through render_trajectory: same function, size and labels."""
    import imageio.v3 as iio

    from taichimyxo.io.trajectory import TrajectoryWriter

    frames = _moving_frames(3, box=(40.0, 40.0))
    for fr in frames:
        fr.meta = {"scene": "S9"}                                      # as sim.frame() labels live frames
    gsd = tmp_path / "S9.gsd"
    with TrajectoryWriter(str(gsd), {"scene": {"name": "S9"}, "cell": {"particles": 8, "width_um": 0.5,
                                                                     "speed_um_per_min": 4.0}}) as tw:
        for fr in frames:
            tw.append(fr)
    scene_png = write_png(frames[-1], tmp_path / "scene.png", color="speed", title="S9", free_speed=4.0)
    n = render_trajectory(gsd, tmp_path / "render.mp4", size=(640, 480), fps=5, png_path=tmp_path / "render.png",
                          progress=False)
    assert n == 3
    render_png = iio.imread(tmp_path / "render.png")[..., :3]
    assert render_png.shape == scene_png.shape
    assert scene_png.shape[:2] == tuple(reversed(frame_size((40.0, 40.0), PNG_SIZE, title="S9")))
    assert np.array_equal(render_png, scene_png)                      # grid positions: the GSD round trip is exact
    # the title comes from the frame's scene when not given
    assert np.array_equal(write_png(frames[-1], tmp_path / "auto.png"), scene_png)
    assert not np.array_equal(write_png(frames[-1], tmp_path / "none.png", title=None), scene_png)


def test_render_trajectory_new_colourings_and_cli(tmp_path, capsys):
    from taichimyxo.interface.cli import main
    from taichimyxo.io.trajectory import TrajectoryWriter

    gsd = tmp_path / "T.gsd"
    with TrajectoryWriter(str(gsd), {"scene": {"name": "T"}, "cell": {"particles": 8}}) as tw:
        for fr in _moving_frames(3):
            tw.append(fr)
    for color in ["identity", "polarity", "orientation"]:
        assert main(["render", str(gsd), "--color", color, "--size", "320x240", "--fps", "5"]) == 0
        assert verify_video(tmp_path / f"T.{color}.mp4") == 3
        assert (tmp_path / f"T.{color}.png").is_file()
    assert main(["render", str(gsd), "--vmin", "2", "--vmax", "6", "--size", "320x240", "--out",
                 str(tmp_path / "range.mp4")]) == 0
    assert verify_video(tmp_path / "range.mp4") == 3
    capsys.readouterr()
    assert main(["render", str(gsd), "--color", "identity", "--vmax", "3"]) == 2
    assert "vmin/vmax" in capsys.readouterr().err
    assert main(["render", str(gsd), "--vmin", "6", "--vmax", "2"]) == 2
    assert not (tmp_path / "T.mp4").exists()


def test_scene_accepts_the_new_colourings():
    from taichimyxo.io.scene import Scene, SceneError

    for color in ["speed", "strain", "identity", "polarity", "orientation"]:
        sc = Scene.from_dict({"output": {"color": color}}, where="test")
        assert sc.raw["output"]["color"] == color
    with pytest.raises(SceneError):
        Scene.from_dict({"output": {"color": "rainbow"}}, where="test")


def test_scene_colour_range_keys():
    """output.color_min / color_max set the movie's range from a scene (render has --vmin / --vmax); refused where
    a colouring has no range, or the range is empty."""
    from taichimyxo.io.scene import Scene, SceneError

    def sc(**out):
        return Scene.from_dict({"domain": {"width_um": 20.0, "height_um": 20.0}, "population": {"cells": 2},
                                "output": {"movie": False, **out}})

    assert sc().color_range == {}
    assert sc(color_min=2.0, color_max=8.0).color_range == {"vmin": 2.0, "vmax": 8.0}
    assert sc(color="strain", color_min=1e-20, color_max=1e-16).color_range == {"vmin": 1e-20, "vmax": 1e-16}
    for bad in ({"color": "identity", "color_max": 5.0}, {"color_min": 8.0, "color_max": 2.0},
                {"color": "strain", "color_max": 1e-17}):
        with pytest.raises(SceneError, match="output.color"):
            sc(**bad)
