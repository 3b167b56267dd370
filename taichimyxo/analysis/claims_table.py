"""The claims table (taichimyxo/analysis/claims.py) as Markdown, CSV and terminal text."""
from __future__ import annotations

import csv
import io
import os

COLUMNS = ("claim", "measured", "paper", "status", "runs")


def to_markdown(rows: list[dict]) -> str:
    esc = lambda s: str(s).replace("|", "\\|").replace("\n", " ")       # noqa: E731
    out = ["| # | " + " | ".join(COLUMNS) + " |", "|---" * (len(COLUMNS) + 1) + "|"]
    for i, r in enumerate(rows, 1):
        out.append(f"| {i} | " + " | ".join(esc(r[c]) for c in COLUMNS) + " |")
    return "\n".join(out) + "\n"


def to_csv(rows: list[dict]) -> str:
    f = io.StringIO()
    w = csv.writer(f)
    w.writerow(("id",) + COLUMNS + ("plot",))
    for r in rows:
        w.writerow([r["id"]] + [r[c] for c in COLUMNS] + [r["plot"] or ""])
    return f.getvalue()


def format_claims(rows: list[dict]) -> str:
    """The table as text for a terminal: one block per claim."""
    out = []
    for i, r in enumerate(rows, 1):
        out.append(f"{i:2d}. {r['claim']}\n    measured: {r['measured']}\n    paper:    {r['paper']}\n"
                   f"    status:   {r['status']}\n    runs:     {r['runs']}")
    return "\n".join(out)


def write_complete(path: str, text: str) -> None:
    """Write text to path through a temporary file: an existing file is replaced only by a complete one."""
    tmp = f"{path}.tmp-{os.getpid()}"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)
