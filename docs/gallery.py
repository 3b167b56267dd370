"""The documentation's gallery: the last frame of every scene's preview, as small images in docs/gallery/.

    python docs/gallery.py                      # every scene `list` shows: their previews, then the images
    python docs/gallery.py --only S1,S3,S8      # some of them
    python docs/gallery.py --no-run             # only the images, from the previews already in --out
    python docs/gallery.py --jobs 2             # previews two at a time (one thread each)

The previews are made by `python -m taichimyxo videos --preview` into --out (default videos/), which skips the
scenes whose preview is already there and up to date, so a second call only redraws the images. Each image is the
preview's figure panel (NAME-preview.png: the last frame with its colour bar, time and scale bar), scaled to
--width pixels; docs/gallery/gallery.json lists them with their titles for the gallery page (docs/hooks.py builds
the page from it when the site is built, so the page shows the images that exist).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
REPO = DOCS.parent
GALLERY = DOCS / "gallery"


def thumbnail(src: Path, dst: Path, width: int) -> None:
    from PIL import Image
    im = Image.open(src).convert("RGB")
    im = im.resize((width, round(im.height * width / im.width)), Image.LANCZOS)
    # a palette image: a tenth of the size of the RGB one, the colour maps still smooth
    im.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(dst, optimize=True)


def main(argv=None) -> int:
    sys.path.insert(0, str(REPO))
    from taichimyxo.io.catalogue import available_scenes
    from taichimyxo.io.scene import Scene

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", help="comma-separated scene names (default: every scene `list` shows)")
    ap.add_argument("--out", default="videos", help="where the previews are made or found (default videos/)")
    ap.add_argument("--jobs", type=int, default=1, help="previews at a time")
    ap.add_argument("--no-run", action="store_true", help="make no preview; draw the images of those in --out")
    ap.add_argument("--width", type=int, default=360, help="image width in pixels (default 360)")
    args = ap.parse_args(argv)

    names = args.only.split(",") if args.only else available_scenes()
    unknown = sorted(set(names) - set(available_scenes()))
    if unknown:
        ap.error(f"unknown scene(s) {', '.join(unknown)}; `python -m taichimyxo list` shows them")
    out = Path(args.out)
    if not args.no_run:
        cmd = [sys.executable, "-m", "taichimyxo", "videos", "--preview", "--out", str(out), "--only", ",".join(names),
               "--jobs", str(args.jobs)]
        if subprocess.run(cmd, cwd=Path.cwd()).returncode != 0:
            print("gallery: some previews failed; drawing those that exist", file=sys.stderr)

    GALLERY.mkdir(exist_ok=True)
    index_path = GALLERY / "gallery.json"
    index = {e["name"]: e for e in json.loads(index_path.read_text())} if index_path.is_file() else {}
    for name in names:
        panel = out / f"{name}-preview.png"
        if not panel.is_file():
            print(f"gallery: {name}: no {panel}, skipped", file=sys.stderr)
            continue
        thumbnail(panel, GALLERY / f"{name}.png", args.width)
        sc = Scene.load(name)
        index[name] = dict(name=name, title=sc.title, paper_figure=sc.paper_figure, image=f"{name}.png")
        print(f"gallery: {GALLERY.relative_to(REPO) / (name + '.png')}")
    order = {n: i for i, n in enumerate(available_scenes())}
    entries = sorted(index.values(), key=lambda e: order.get(e["name"], len(order)))
    index_path.write_text(json.dumps(entries, indent=1, ensure_ascii=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
