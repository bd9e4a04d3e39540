"""HTML pages for the studies (``clothlab bench --report``, ``clothlab check --report``): the JSON figures of a
run rendered as tables - lists of flat records become tables, nested mappings become sections, scalars a
facts table - with the run's PNG figures.  Files in, files out; written atomically."""

from __future__ import annotations

import json
from pathlib import Path

from clothlab.report.html import _page, _table, esc, fmt_number

MAX_ROWS = 400


def _cell(value) -> tuple[str, str] | str:
    if isinstance(value, bool) or value is None:
        return esc(value)
    if isinstance(value, int | float):
        return ("num", fmt_number(value))
    if isinstance(value, list | dict):
        return f"<code>{esc(json.dumps(value, default=str)[:160])}</code>"
    return esc(value)


def _render(key: str, value, depth: int) -> list[str]:
    heading = f"<h{min(depth, 4)}>{esc(key)}</h{min(depth, 4)}>"
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        columns = list(dict.fromkeys(k for row in value for k in row))
        flat = [c for c in columns if not any(isinstance(r.get(c), list | dict) and len(json.dumps(r.get(c))) > 160
                                              for r in value)]
        rows = [[_cell(r.get(c)) for c in flat] for r in value[:MAX_ROWS]]
        more = f'<p class="note">({len(value) - MAX_ROWS} more rows in the JSON)</p>' if len(value) > MAX_ROWS else ""
        return [heading, _table([esc(c) for c in flat], rows), more]
    if isinstance(value, dict):
        scalars = {k: v for k, v in value.items() if not isinstance(v, dict | list) or
                   (isinstance(v, list) and not all(isinstance(x, dict) for x in v))}
        out = [heading]
        if scalars:
            out.append(_table(["", ""], [[esc(k), _cell(v)] for k, v in scalars.items()]))
        for k, v in value.items():
            if k not in scalars:
                out += _render(k, v, depth + 1)
        return out
    return [heading, f"<p>{esc(value)}</p>"]


def write_study_report(result: dict, dest, *, title: str, figures=()) -> Path:
    """``dest``/index.html (+ copies of the figure PNGs and result.json); returns the page's path."""
    import shutil

    from clothlab.atomic import atomic_write_text

    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    body = [f"<h1>{esc(title)}</h1>"]
    for figure in figures:
        figure = Path(figure)
        if figure.is_file():
            if figure.parent.resolve() != dest.resolve():
                shutil.copy(figure, dest / figure.name)
            body.append(f'<figure><img src="{esc(figure.name)}" alt="{esc(figure.stem)}" style="max-width:100%">'
                        f"<figcaption>{esc(figure.stem)}</figcaption></figure>")
    body += _render("Figures of this run", result, 2)
    atomic_write_text(dest / "result.json", json.dumps(result, indent=1, default=float) + "\n")
    return atomic_write_text(dest / "index.html", _page(title, body))
