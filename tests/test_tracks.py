"""Lab tracks in (taichimyxo/io/tracks.py) and their measures (taichimyxo/analysis/lab_tracks.py), on synthetic tracks
whose answers are known: speeds, reversals, gaps, identity swaps, TrackMate's and a plain CSV, bad input."""
import numpy as np
import pytest

from taichimyxo.analysis.lab_tracks import reversals, speed_distribution, step_speeds
from taichimyxo.io.tracks import TracksError, assemble, from_frames, read_tracks

FRAME_S = 30.0
V = 4.0 / 60.0                                   # v_b, µm/s


def straight(n=40, v=V, start=(0.0, 0.0), angle=0.0, reverse_every=None):
    """One cell moving at v, turning back every `reverse_every` points."""
    t = np.arange(n) * FRAME_S
    direction = np.ones(n)
    if reverse_every:
        direction = np.where((np.arange(n) // reverse_every) % 2 == 0, 1.0, -1.0)
    s = np.concatenate([[0.0], np.cumsum(direction[:-1] * v * FRAME_S)])
    xy = np.asarray(start) + s[:, None] * np.array([np.cos(angle), np.sin(angle)])
    return t, xy


def table(tracks):
    ids = np.concatenate([np.full(len(t), k) for k, (t, _) in enumerate(tracks)])
    return ids, np.concatenate([t for t, _ in tracks]), np.concatenate([xy for _, xy in tracks])


def test_speeds_of_cells_at_v_b_and_at_twice_it():
    ids, ts, xy = table([straight(), straight(v=2 * V, start=(0, 50))])
    tr = assemble(ids, ts, xy, FRAME_S)
    s = step_speeds(tr)
    assert len(s) == 78 and np.allclose(np.sort(s), [4.0] * 39 + [8.0] * 39)
    d = speed_distribution(tr)
    assert d["mean_vb"] == pytest.approx(1.5) and d["median_vb"] == pytest.approx(1.5) and d["steps"] == 78


def test_reversals_every_ten_frames_are_counted_with_their_run_durations():
    t, xy = straight(n=61, reverse_every=10)
    tr = assemble(*table([(t, xy)]), FRAME_S)
    r = reversals(tr)
    assert r["reversals"] == 5                                     # turns at points 10, 20, ..., 50
    assert np.allclose(r["run_durations_s"], 10 * FRAME_S)
    assert r["per_cell_hour"] == pytest.approx(5 / (60 * FRAME_S / 3600))
    assert reversals(assemble(*table([straight(n=61)]), FRAME_S))["reversals"] == 0


def test_gaps_and_identity_swaps_split_tracks_and_are_counted():
    t, xy = straight(n=30)
    keep = np.ones(30, bool)
    keep[10:14] = False                                            # 4 frames missing: longer than 2
    t1, xy1 = t[keep], xy[keep]
    t2, xy2 = straight(n=30, start=(0, 20))
    xy2 = xy2.copy()
    xy2[15:] += np.array([0.0, 25.0])                              # another cell's path from frame 15 on: a swap
    tr = assemble(*table([(t1, xy1), (t2, xy2), straight(n=3, start=(0, 80))]), FRAME_S)
    c = tr.counts
    assert (c["tracks_read"], c["split_at_gaps"], c["split_at_jumps"], c["pieces_too_short"]) == (3, 1, 1, 1)
    assert c["tracks_kept"] == 4 and sorted(len(a) for a, _ in tr.tracks) == [10, 15, 15, 16]


TRACKMATE = """LABEL,ID,TRACK_ID,QUALITY,POSITION_X,POSITION_Y,POSITION_Z,POSITION_T,FRAME
Label,Spot ID,Track ID,Quality,X,Y,Z,T,Frame
Label,Spot ID,Track ID,Quality,X,Y,Z,T,Frame
,,,(quality),(micron),(micron),(micron),(sec),
{rows}"""


def test_trackmate_spots_table_and_a_plain_csv_in_pixels_and_frames(tmp_path):
    rows = []
    for k, (t, xy) in enumerate([straight(n=12), straight(n=12, start=(0, 30))]):
        rows += [f"ID{k}{i},{k},{k},1.0,{x:.6f},{y:.6f},0,{ti:.1f},{i}" for i, (ti, (x, y)) in enumerate(zip(t, xy))]
    rows.append("ID99,99,,1.0,5,5,0,30.0,1")                         # a spot in no track
    f = tmp_path / "spots.csv"
    f.write_text(TRACKMATE.format(rows="\n".join(rows)))
    tr = read_tracks(f)
    assert tr.counts["tracks_kept"] == 2 and tr.counts["spots_without_track"] == 1
    assert np.allclose(step_speeds(tr), 4.0)
    g = tmp_path / "plain.csv"                                       # pixels of 0.5 µm, times in frames of 30 s
    t, xy = straight(n=12)
    g.write_text("track,frame,x,y\n" + "".join(f"7,{i},{x / 0.5},{y / 0.5}\n" for i, (x, y) in enumerate(xy)))
    tr = read_tracks(g, pixel_um=0.5, frame_s=30.0, time_unit="frame")
    assert np.allclose(step_speeds(tr), 4.0)


def test_bad_tracks_input_is_one_line_naming_the_file_or_value(tmp_path):
    f = tmp_path / "t.csv"
    f.write_text("cell,time,x\n1,0,0\n")
    g = tmp_path / "frames.csv"
    g.write_text("track,frame,x,y\n1,0,0,0\n1,1,1,0\n")
    for call, message in [(lambda: read_tracks(tmp_path / "none.csv"), "not found"),
                          (lambda: read_tracks(f), "no 'y' column"),
                          (lambda: read_tracks(f, pixel_um=-1), "pixel size -1"),
                          (lambda: read_tracks(g, time_unit="frame"), "need the frame interval")]:
        with pytest.raises(TracksError) as e:
            call()
        assert message in str(e.value) and "\n" not in str(e.value)


def test_a_simulation_gives_the_same_tracks_through_its_centroids():
    """from_frames: the centroids of a simulation's cells, unwrapped across the periodic box, as tracks."""
    from types import SimpleNamespace
    frames = []
    for k in range(20):
        x = (19.0 + k * V * FRAME_S) % 20.0                          # crosses the box's edge at 20 µm
        pos = np.stack([np.array([[x + 0.1 * i, 5.0] for i in range(8)])])
        frames.append(SimpleNamespace(positions=pos, time_s=k * FRAME_S, box=(20.0, 20.0)))
    tr = from_frames(frames)
    assert tr.counts["tracks_kept"] == 1 and np.allclose(step_speeds(tr), 4.0)


MODEL_XML = """<?xml version="1.0" encoding="UTF-8"?>
<TrackMate version="7.11.1"><Model spatialunits="micron" timeunits="{unit}"><AllSpots nspot="{n}">{spots}</AllSpots>
<AllTracks>{tracks}</AllTracks><FilteredTracks>{kept}</FilteredTracks></Model>
<Settings><ImageData filename="movie.tif" pixelwidth="0.1" timeinterval="30.0"/></Settings></TrackMate>"""


def model_xml(path, cells, kept=None, stray=0, unit="sec", with_t=True):
    """A TrackMate model file: cells[k] = (t, xy) becomes track k (its spots chained by edges); `stray` spots in no
    track; FilteredTracks lists `kept` (default all)."""
    spots, tracks, sid = [], [], 0
    for k, (t, xy) in enumerate(cells):
        ids = []
        for i, (ti_, (x, y)) in enumerate(zip(t, xy)):
            tt = f' POSITION_T="{ti_ / (60.0 if unit == "min" else 1.0):g}"' if with_t else ""
            spots.append(f'<Spot ID="{sid}" POSITION_X="{x:g}" POSITION_Y="{y:g}"{tt} FRAME="{i}"/>')
            ids.append(sid)
            sid += 1
        edges = "".join(f'<Edge SPOT_SOURCE_ID="{a}" SPOT_TARGET_ID="{b}"/>' for a, b in zip(ids, ids[1:]))
        tracks.append(f'<Track name="Track_{k}" TRACK_ID="{k}">{edges}</Track>')
    for j in range(stray):
        spots.append(f'<Spot ID="{sid + j}" POSITION_X="90" POSITION_Y="90" POSITION_T="0" FRAME="0"/>')
    kept = range(len(cells)) if kept is None else kept
    path.write_text(MODEL_XML.format(unit=unit, n=len(spots), spots="".join(spots), tracks="".join(tracks),
                                     kept="".join(f'<TrackID TRACK_ID="{k}"/>' for k in kept)))
    return path


def test_trackmate_model_xml_reads_tracks_from_edges_honours_filtered_tracks_and_counts_strays(tmp_path):
    cells = [straight(n=20), straight(n=20, start=(0, 30)), straight(n=20, start=(0, 60))]
    tr = read_tracks(model_xml(tmp_path / "m.xml", cells, kept=[0, 2], stray=3))
    assert tr.counts["tracks_kept"] == 2 and tr.counts["spots_without_track"] == 20 + 3
    assert tr.frame_s == pytest.approx(FRAME_S)
    ys = sorted(float(xy[0, 1]) for _, xy in tr.tracks)
    assert ys == [0.0, 60.0] and np.allclose(step_speeds(tr), 4.0)
    # minutes in the file, or frames only (then the settings' interval): the same tracks in s
    for kw in (dict(unit="min"), dict(with_t=False)):
        t2 = read_tracks(model_xml(tmp_path / "m2.xml", cells, **kw))
        assert np.allclose(t2.tracks[0][0], cells[0][0]) and np.allclose(step_speeds(t2), 4.0)


def test_trackmate_tracks_export_xml_counts_frames_at_its_interval(tmp_path):
    parts = "".join('<particle nSpots="20">' + "".join(
        f'<detection t="{i}" x="{x:g}" y="{y:g}" z="0"/>' for i, (x, y) in enumerate(straight(n=20, start=(0, k))[1]))
        + "</particle>" for k in (0, 40))
    f = tmp_path / "e.xml"
    f.write_text(f'<?xml version="1.0"?><Tracks nTracks="2" spaceUnits="micron" frameInterval="0.5" timeUnits="min" '
                 f'from="TrackMate v7">{parts}</Tracks>')
    tr = read_tracks(f)
    assert tr.counts["tracks_kept"] == 2 and tr.frame_s == pytest.approx(30.0)
    assert np.allclose(step_speeds(tr), 4.0)


@pytest.mark.parametrize("text, words", [("<a><b/></a>", "not TrackMate's"), ("<Tracks", "not readable as XML"),
                                         ('<Tracks><particle><detection t="0" y="1"/></particle></Tracks>',
                                          "detection without a number for x")])
def test_bad_xml_is_one_line_naming_the_file(tmp_path, text, words):
    f = tmp_path / "bad.xml"
    f.write_text(text)
    with pytest.raises(TracksError, match=words) as e:
        read_tracks(f)
    assert str(f) in str(e.value) and "\n" not in str(e.value)
