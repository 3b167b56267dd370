"""Off-screen renderer (taichimyxo.render): colours at the right pixels, periodic copies, MP4 and PNG output, GSD."""
from __future__ import annotations

import matplotlib
import numpy as np
import pytest

from taichimyxo.io.frame import Frame
from taichimyxo.render import (
    Renderer,
    VideoWriteError,
    VideoWriter,
    render_frame,
    render_trajectory,
    speed_scale,
    strain_scale,
    verify_video,
    write_png,
)
from taichimyxo.render.raster import format_time, get_renderer, nice_scalebar_length
from taichimyxo.render.video import even_size

TURBO = matplotlib.colormaps["turbo"]
SIZE = (400, 440)
BOX = (20.0, 20.0)
WHITE = np.array([255, 255, 255], np.uint8)


def turbo(x) -> np.ndarray:
    """The colour matplotlib's turbo gives to normalised value x, as uint8 RGB."""
    return np.asarray(TURBO(x, bytes=True), np.uint8)[..., :3]


def straight_cell(start, end, n=8) -> np.ndarray:
    return np.linspace(np.asarray(start, float), np.asarray(end, float), n)


def make_frame(cells, speeds, box=BOX, strain=None, time_s=0.0, width=0.5) -> Frame:
    pos = np.stack(cells).astype(np.float64)
    spd = np.broadcast_to(np.asarray(speeds, np.float32).reshape(-1, 1), pos.shape[:2]).copy()
    return Frame(time_s=time_s, step=0, box=box, width_um=width, positions=pos,
                 engine_direction=np.ones(len(pos), np.int8), particle_speed=spd,
                 segment_strain=None if strain is None else np.asarray(strain, np.float64))


def pixel(img, vp, xy):
    r, c = vp.to_pixel(np.asarray(xy, float))
    return img[int(r), int(c)]


# ------------------------------------------------------------------------------------------------ colour scales

def test_speed_scale_is_turbo_linear_0_16():
    sc = speed_scale()
    v = np.concatenate([np.linspace(0, 16, 1001), [-3.0, 0.0, 16.0, 40.0, np.nan]])
    x = np.clip(np.nan_to_num(v / 16.0), 0, 1)
    assert np.array_equal(sc.rgb(v), turbo(x))
    assert sc.ticks == (0.0, 4.0, 8.0, 12.0, 16.0)
    assert "min" in sc.label and "m" in sc.label


def test_strain_scale_is_log10_with_zero_at_bottom():
    sc = strain_scale()
    assert (sc.vmin, sc.vmax) == (1e-21, 1e-17)
    e = np.array([0.0, 1e-25, 1e-21, 1e-20, 1e-19, 3e-19, 1e-18, 1e-17, 1e-12])
    x = np.clip((np.log10(np.maximum(e, 1e-30)) + 21.0) / 4.0, 0, 1)
    assert np.array_equal(sc.rgb(e), turbo(x))
    assert np.array_equal(sc.rgb([0.0])[0], turbo(0.0))
    assert sc.label == "strain energy, J"


# ------------------------------------------------------------------------------------------------ pixels

def test_single_cell_has_its_speed_colour_and_background_elsewhere():
    speed = 6.0
    fr = make_frame([straight_cell((6.0, 10.0), (14.0, 10.0))], [speed])
    img = render_frame(fr, size=SIZE)
    r = get_renderer(BOX, SIZE, "speed")
    vp = r.viewport
    w, h = r.size                                                        # fitted to the square box within SIZE
    assert img.shape == (h, w, 3) and img.dtype == np.uint8
    assert h == SIZE[1] and w <= SIZE[0] and w % 2 == 0 and h % 2 == 0
    want = turbo(speed / 16.0)
    assert np.array_equal(pixel(img, vp, (10.0, 10.0)), want)            # the centre of the cell
    for x in np.linspace(6.0, 14.0, 9):                                   # along the whole axis, caps included
        assert np.array_equal(pixel(img, vp, (x, 10.0)), want)
    assert np.array_equal(pixel(img, vp, (10.0, 10.12)), want)           # inside the width (W/2 = 0.25 µm)
    for xy in [(10.0, 10.6), (10.0, 9.4), (5.5, 10.0), (14.5, 10.0), (3.0, 3.0), (17.0, 15.0)]:
        assert np.array_equal(pixel(img, vp, xy), WHITE), xy
    # nothing but background and the cell's antialiased edge inside the box
    box = img[vp.slices]
    coloured = np.any(box != WHITE, axis=-1)
    rows, cols = np.nonzero(coloured)
    xy = vp.to_data(rows + vp.row0, cols + vp.col0)
    assert np.all(np.abs(xy[:, 1] - 10.0) < 0.25 + 1.5 / vp.scale)
    assert np.all((xy[:, 0] > 6.0 - 0.25 - 1.5 / vp.scale) & (xy[:, 0] < 14.0 + 0.25 + 1.5 / vp.scale))


def test_each_segment_has_its_own_colour():
    cell = straight_cell((2.0, 5.0), (16.0, 5.0), n=8)                   # 7 segments of 2 µm
    speeds = np.array([[0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0]], np.float32)
    fr = make_frame([cell], [0.0])
    fr.particle_speed = speeds
    img = render_frame(fr, size=SIZE)
    vp = get_renderer(BOX, SIZE, "speed").viewport
    seg_speed = 0.5 * (speeds[0, 1:] + speeds[0, :-1])
    mids = 0.5 * (cell[1:] + cell[:-1])
    for m, v in zip(mids, seg_speed):
        assert np.array_equal(pixel(img, vp, m), turbo(v / 16.0))


def test_colour_bar_ends_have_the_colours_of_0_and_16():
    r = get_renderer(BOX, SIZE, "speed")
    img = render_frame(make_frame([straight_cell((6, 10), (14, 10))], [3.0]), size=SIZE)
    r0, r1, c0, c1 = r.layout.colorbar
    assert r1 > r0 and c1 - c0 > 50
    mid = (r0 + r1) // 2
    assert np.array_equal(img[mid, c0], turbo(0.0))
    assert np.array_equal(img[mid, c1 - 1], turbo(1.0))
    # the bar lies below the box, inside the image
    assert r0 > r.viewport.row0 + r.viewport.height and r1 < SIZE[1]
    # monotone along the bar: left half cooler (bluer) than the right half is red
    assert img[mid, c1 - 1, 0] > img[mid, c0, 0]


def test_strain_colours_a_known_overlap():
    # two one-segment cells, parallel, axes 0.4 µm apart: overlap W - d = 0.1 µm. Strain energy of the pair
    # 1/2 k_c (W - d)^2 with k_c = 0.01 N/m, half to each segment.
    k_c, W, d = 0.01, 0.5e-6, 0.4e-6
    e_seg = 0.5 * 0.5 * k_c * (W - d) ** 2                                # 1.25e-17 J
    a = straight_cell((5.0, 10.0), (15.0, 10.0), n=2)
    b = straight_cell((5.0, 10.4), (15.0, 10.4), n=2)
    c = straight_cell((5.0, 4.0), (15.0, 4.0), n=2)                       # a free cell: zero strain
    fr = make_frame([a, b, c], [4.0, 4.0, 4.0], strain=[[e_seg], [e_seg], [0.0]])
    img = render_frame(fr, size=SIZE, color="strain")
    vp = get_renderer(BOX, SIZE, "strain").viewport
    x = (np.log10(e_seg) + 21.0) / 4.0
    assert np.array_equal(pixel(img, vp, (10.0, 9.95)), turbo(x))         # cell a, on the side away from b
    assert np.array_equal(pixel(img, vp, (10.0, 10.45)), turbo(x))        # cell b
    assert np.array_equal(pixel(img, vp, (10.0, 4.0)), turbo(0.0))        # no overlap: bottom colour
    with pytest.raises(ValueError, match="strain"):
        render_frame(make_frame([a], [4.0]), size=SIZE, color="strain")


def test_cell_across_the_periodic_edge_appears_on_both_sides():
    # particle 0 inside the box at x = 18, chain unwrapped out to x = 23 (= 3 on the other side)
    fr = make_frame([straight_cell((18.0, 7.0), (23.0, 7.0))], [8.0])
    img = render_frame(fr, size=SIZE)
    vp = get_renderer(BOX, SIZE, "speed").viewport
    want = turbo(0.5)
    assert np.array_equal(pixel(img, vp, (19.0, 7.0)), want)
    assert np.array_equal(pixel(img, vp, (1.5, 7.0)), want)               # the wrapped copy, left side
    assert np.array_equal(pixel(img, vp, (5.0, 7.0)), WHITE)
    # nothing is drawn outside the box (the outline frame is just outside it)
    r = get_renderer(BOX, SIZE, "speed")
    row = int(vp.to_pixel((0.0, 7.0))[0])
    assert np.array_equal(img[row, vp.col0 + vp.width + 3], WHITE)
    assert np.array_equal(img[row, vp.col0 - 3], WHITE)
    assert r.viewport is vp


def test_cell_across_a_corner_appears_in_all_four_corners():
    fr = make_frame([straight_cell((19.0, 19.0), (22.0, 22.0))], [16.0])
    img = render_frame(fr, size=SIZE)
    vp = get_renderer(BOX, SIZE, "speed").viewport
    for xy in [(19.5, 19.5), (0.5, 0.5), (19.9, 0.1), (0.1, 19.9)]:
        assert np.array_equal(pixel(img, vp, xy), turbo(1.0)), xy


def test_viewport_round_trip_and_layout():
    r = Renderer((640, 480), "speed", (30.0, 10.0))
    vp = r.viewport
    assert vp.width <= 640 and abs(vp.width / vp.height - 3.0) < 0.05    # aspect ratio kept
    rows, cols = np.mgrid[vp.row0:vp.row0 + vp.height:7, vp.col0:vp.col0 + vp.width:7]
    xy = vp.to_data(rows, cols)
    r2, c2 = vp.to_pixel(xy)
    assert np.array_equal(r2, rows) and np.array_equal(c2, cols)
    assert vp.to_pixel((0.0, 10.0)) == (vp.row0, vp.col0)                 # top-left corner of the box (y up)
    assert nice_scalebar_length(200.0) == 50.0 and nice_scalebar_length(60.0) == 10.0
    assert nice_scalebar_length(100.0) == 25.0


def test_time_is_shown_as_h_min():
    assert format_time(0.0) == "t = 0 min"
    assert format_time(6 * 60.0) == "t = 6 min"                          # not "0:06 h", which reads as 0.06 h
    assert format_time(59 * 60.0 + 59.0) == "t = 59 min"
    assert format_time(3600.0) == "t = 1 h 00 min"
    assert format_time(65 * 60.0) == "t = 1 h 05 min"
    assert format_time(3 * 3600 + 45 * 60 + 59.0) == "t = 3 h 45 min"
    assert format_time(59.99999999) == "t = 1 min"
    a = render_frame(make_frame([straight_cell((6, 10), (14, 10))], [3.0], time_s=0.0), size=SIZE)
    b = render_frame(make_frame([straight_cell((6, 10), (14, 10))], [3.0], time_s=3600.0), size=SIZE)
    diff = np.any(a != b, axis=-1)
    vp = get_renderer(BOX, SIZE, "speed").viewport
    assert diff.any() and not diff[vp.slices].any()                        # only the time text changed


def test_title_is_drawn_under_the_box_only():
    fr = make_frame([straight_cell((6, 10), (14, 10))], [3.0])
    a = render_frame(fr, size=SIZE)
    b = render_frame(fr, size=SIZE, title="S3")
    vp = get_renderer(BOX, SIZE, "speed", title="S3").viewport
    diff = np.any(a != b, axis=-1)
    rows = np.nonzero(diff)[0]
    assert len(rows) and rows.min() > vp.row0 + vp.height


# ------------------------------------------------------------------------------------------------ files

def _frames(n=4, box=BOX):
    out = []
    for i in range(n):
        cells = [straight_cell((2.0 + i, 5.0), (9.0 + i, 5.0)),           # steps of 1 µm: exact in float32
                 straight_cell((16.0, 12.0 + i), (23.0, 15.5 + i))]      # crosses the edge x = 20
        out.append(make_frame(cells, [2.0 * i, 16.0 - i], box=box, time_s=60.0 * i))
    return out


def test_mp4_opens_with_expected_frames_and_size(tmp_path):
    import imageio

    path = tmp_path / "movie.mp4"
    frames = _frames(5)
    with VideoWriter(path, size=(321, 241), fps=10, title="test") as vw:
        assert vw.size == (322, 242)                                      # forced even for yuv420p
        for fr in frames:
            vw.append(fr)
        w, h = vw.size                                                     # the square box's frame within it
        assert h == 242 and w < 322 and w % 2 == 0
    vw.close()                                                             # idempotent
    assert vw.closed and vw.frames_written == 5
    assert verify_video(path, 5) == 5
    rd = imageio.get_reader(str(path), "ffmpeg")
    try:
        imgs = [im for im in rd]
        meta = rd.get_meta_data()
    finally:
        rd.close()
    assert len(imgs) == 5
    assert imgs[0].shape == (h, w, 3)
    assert meta["codec"] == "h264" and abs(meta["fps"] - 10) < 1e-6
    # the decoded picture is the rendered one, up to compression
    ref = render_frame(frames[-1], size=(322, 242), title="test").astype(int)
    assert ref.shape == (h, w, 3)
    assert np.abs(imgs[-1].astype(int) - ref).mean() < 6
    with pytest.raises(ValueError):
        vw.append(frames[0])


def test_video_writer_without_frames_writes_nothing_and_bad_files_are_reported(tmp_path):
    vw = VideoWriter(tmp_path / "empty.mp4", size=(64, 64))
    vw.close()
    assert not (tmp_path / "empty.mp4").exists()
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a movie at all")
    with pytest.raises(VideoWriteError):
        verify_video(bad, 3)
    with pytest.raises(VideoWriteError):
        verify_video(tmp_path / "missing.mp4")
    with pytest.raises(ValueError, match="color"):
        VideoWriter(tmp_path / "x.mp4", color="colour").append(_frames(1)[0])
    assert even_size((1919, 1080)) == (1920, 1080)


def test_write_png_is_the_rendered_image(tmp_path):
    import imageio.v3 as iio

    fr = _frames(2)[-1]
    img = write_png(fr, tmp_path / "panel.png", size=(300, 330))
    back = iio.imread(tmp_path / "panel.png")
    assert np.array_equal(back[..., :3], img)
    assert np.array_equal(img, render_frame(fr, size=(300, 330)))


def test_render_trajectory_equals_render_frame(tmp_path):
    import imageio.v3 as iio

    from taichimyxo.io.trajectory import TrajectoryWriter, read_frames

    # positions on a 1/64 µm grid, float32 speeds and strain: the GSD round trip is exact
    frames = _frames(3)
    for fr in frames:
        fr.segment_strain = np.full((fr.n_cells, fr.particles_per_cell - 1), np.float32(3e-18), np.float64)
    gsd = tmp_path / "traj.gsd"
    with TrajectoryWriter(str(gsd), {"cell": {"particles": 8, "width_um": 0.5}}) as tw:
        for fr in frames:
            tw.append(fr)
    size = (256, 282)
    for color in ("speed", "strain"):
        n = render_trajectory(gsd, tmp_path / f"{color}.mp4", color=color, size=size, fps=5,
                              png_path=tmp_path / f"{color}.png", png_size=size, progress=False, title="traj")
        assert n == 3
        assert verify_video(tmp_path / f"{color}.mp4") == 3
        png = iio.imread(tmp_path / f"{color}.png")[..., :3]
        assert np.array_equal(png, render_frame(frames[-1], size=size, color=color, title="traj"))
    for fr, back in zip(frames, read_frames(str(gsd))):
        assert np.array_equal(render_frame(back, size=size), render_frame(fr, size=size))
    assert render_trajectory(gsd, tmp_path / "every2.mp4", size=size, every=2, progress=False) == 2

    # a trajectory without strain: one clear error, no movie
    gsd2 = tmp_path / "nostrain.gsd"
    with TrajectoryWriter(str(gsd2), {"cell": {"particles": 8}}) as tw:
        for fr in _frames(2):
            tw.append(fr)
    with pytest.raises(ValueError, match="no strain"):
        render_trajectory(gsd2, tmp_path / "nostrain.mp4", color="strain", size=size, progress=False)
    assert not (tmp_path / "nostrain.mp4").exists()
    # ... unless told the contact law: the strain energy computed from each frame's positions
    assert render_trajectory(gsd2, tmp_path / "computed.mp4", color="strain", size=size, progress=False,
                             strain_from=(0.5, 10.0)) == 2
    assert (tmp_path / "computed.mp4").stat().st_size > 0
