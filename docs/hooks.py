"""mkdocs hooks (mkdocs.yml `hooks:`): two pages built from files when the site is built.

- tutorial.md shows docs/tutorial.ipynb: its markdown cells as they are, its code cells as Python blocks (the
  notebook is committed without outputs; CI executes it). No Jupyter package is needed to build the site.
- gallery.md gets a grid of the images docs/gallery.py made (docs/gallery/gallery.json), so the page shows exactly
  the images that exist.
"""
from __future__ import annotations

import json
from pathlib import Path

DOCS = Path(__file__).resolve().parent
MARKER = "<!-- generated -->"


def notebook_markdown(path: Path) -> str:
    nb = json.loads(path.read_text())
    parts = []
    for cell in nb["cells"]:
        src = "".join(cell["source"]).rstrip()
        if not src:
            continue
        parts.append(src if cell["cell_type"] == "markdown" else f"```python\n{src}\n```")
    return "\n\n".join(parts) + "\n"


def gallery_markdown(index_path: Path) -> str:
    entries = json.loads(index_path.read_text()) if index_path.is_file() else []
    entries = [e for e in entries if (index_path.parent / e["image"]).is_file()]
    if not entries:
        return "*No images yet: run `python docs/gallery.py`.*\n"
    cells = []
    for e in entries:
        fig = f" ({e['paper_figure']})" if e.get("paper_figure") else ""
        cells.append(f'<figure markdown="span">\n  ![{e["name"]}](gallery/{e["image"]}){{ width="300" }}\n'
                     f'  <figcaption><b>{e["name"]}</b>: {e["title"]}{fig}</figcaption>\n</figure>')
    return '<div class="grid" markdown>\n\n' + "\n\n".join(cells) + "\n\n</div>\n"


def on_page_markdown(markdown, page, config, files):
    if page.file.src_uri == "tutorial.md":
        return markdown.replace(MARKER, notebook_markdown(DOCS / "tutorial.ipynb"))
    if page.file.src_uri == "gallery.md":
        return markdown.replace(MARKER, gallery_markdown(DOCS / "gallery" / "gallery.json"))
    return markdown
