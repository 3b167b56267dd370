"""The mechanism report on a public data set of real M. xanthus tracks (docs/lab-tracks.md "A real example"): the
Igoshin group's circular-aggregate tracks (Balagam et al., mSystems 2021, Fig 3: fluorescently labelled cells, 1 in
250, in a swarm of TraAB-overexpressing cells forming circular aggregates, 16 h, 60 frames 1 min apart, positions
in µm at 0.5136 µm per pixel). The data are not shipped with taichimyxo (their repository states no licence):

    git clone https://github.com/Igoshin-Group/CA_paper_data
    pip install mat-io                        # reads the MATLAB table the tracks are stored in
    python -m taichimyxo sweep sweeps/mechanisms.toml --out REFS
    python benchmarks/lab_example.py CA_paper_data --refs REFS --out lab-example

Writes tracks.csv (track, frame, x_um, y_um: the table as the `tracks` command reads it) and the report
(tracks.json, report.md, report.json, report.png) into --out.
"""
from __future__ import annotations

import sys
from pathlib import Path

from benchlib import parser

FRAME_S = 60.0


def convert(mat: Path, csv: Path) -> int:
    """The MATLAB table m_tracks1 of mtracks.mat as a CSV of track, frame, x_um, y_um; returns the rows."""
    try:
        import matio
    except ImportError:
        raise SystemExit("lab_example: reading mtracks.mat needs the package mat-io: pip install mat-io") from None
    import numpy as np
    props = matio.load_from_mat(str(mat), variable_names=["m_tracks1"])["m_tracks1"].properties
    names = [str(np.asarray(v).ravel()[0]) for v in props["varnames"].ravel()]
    cols = {n: np.asarray(a).ravel() for n, a in zip(names, props["data"].ravel())}
    with open(csv, "w") as f:
        f.write("track,frame,x_um,y_um\n")
        for k, fr, x, y in zip(cols["id"], cols["frame"], cols["x"], cols["y"]):
            f.write(f"{int(k)},{int(fr)},{x:.4f},{y:.4f}\n")
    return len(cols["id"])


def main(argv=None) -> int:
    p = parser(__doc__)
    p.add_argument("data", help="the cloned CA_paper_data folder, or its 'Fig 3/mtracks.mat'")
    p.add_argument("--refs", action="append", default=[], help="simulated runs of the mechanisms "
                                                               "(sweeps/mechanisms.toml's --out); repeatable")
    p.add_argument("--v-b", type=float, default=None, help="the cells' free speed, µm/min (default: from the tracks)")
    a = p.parse_args(argv)
    data = Path(a.data)
    mat = data / "Fig 3" / "mtracks.mat" if data.is_dir() else data
    if not mat.is_file():
        print(f"lab_example: {mat} not found; clone https://github.com/Igoshin-Group/CA_paper_data", file=sys.stderr)
        return 2
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    n = convert(mat, out / "tracks.csv")
    print(f"{n} spots from {mat} -> {out / 'tracks.csv'}", file=sys.stderr)
    from taichimyxo.interface.cli import main as cli
    args = ["tracks", str(out / "tracks.csv"), "--frame-s", str(FRAME_S), "--time-unit", "frame", "--out", str(out)]
    args += [x for r in a.refs for x in ("--against", r)]
    if a.quick:
        args += ["--boot", "100"]
    if a.v_b:
        args += ["--v-b", str(a.v_b)]
    return cli(args)


if __name__ == "__main__":
    sys.exit(main())
