"""``index.html``: one self-contained page (no network: inline CSS, no scripts, images and movie beside it)."""

from __future__ import annotations

import json
import logging
import platform
from html import escape
from pathlib import Path
from typing import Any

from wptrack.io.atomic import atomic_write_text
from wptrack.report.model import ReportContext, Section

log = logging.getLogger(__name__)

INDEX_FILE = "index.html"

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0;color:#222;background:#fafafa}
header{background:#1f2d4d;color:#fff;padding:14px 24px}
header h1{margin:0;font-size:22px} header p{margin:4px 0 0;color:#cdd6ea}
main{padding:8px 24px 40px;max-width:1500px}
nav a{margin-right:14px;color:#1f4fb0}
h2{border-bottom:2px solid #dde;padding-bottom:4px;margin-top:34px}
table{border-collapse:collapse;margin:8px 0;font-size:14px}
td,th{border:1px solid #ddd;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#eef1f7}
.grid{display:flex;flex-wrap:wrap;gap:18px;align-items:flex-start}
.cards{display:flex;flex-wrap:wrap;gap:18px;align-items:flex-start}
figure{margin:0;background:#fff;border:1px solid #ddd;padding:6px;max-width:calc(50% - 24px)}
figure.wide{max-width:calc(100% - 14px)}
@media (max-width:1100px){figure{max-width:calc(100% - 14px)}}
figure img,figure video{max-width:100%;height:auto;display:block}
figcaption{font-size:13px;color:#555;padding-top:4px;max-width:820px}
.note{background:#fff6d9;border-left:4px solid #e0b000;padding:4px 10px;margin:6px 0;font-size:14px}
pre{background:#f2f2f2;padding:8px;overflow:auto;font-size:12px;max-height:480px}
.muted{color:#777}
"""


def _table(rows: list[tuple[str, Any]], header: tuple[str, str] | None = None) -> str:
    if not rows:
        return ""
    out = ["<table>"]
    if header:
        out.append(f"<tr><th>{escape(header[0])}</th><th>{escape(header[1])}</th></tr>")
    for k, v in rows:
        out.append(f"<tr><th>{escape(str(k))}</th><td>{escape(str(v))}</td></tr>")
    out.append("</table>")
    return "".join(out)


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(_fmt(v) for v in value)
    if value is None:
        return "-"
    return str(value)


def _figure_html(fig: Any) -> str:
    src = escape(fig.path, quote=True)
    cap = escape(fig.caption)
    links = "".join(f' <a href="{escape(a, quote=True)}" download>{escape(a)}</a>' for a in fig.alternates)
    if links:
        cap += f" <span class='muted'>(download:{links})</span>"
    if fig.kind == "video":
        mime = "video/webm" if fig.path.endswith(".webm") else "video/mp4"
        body = (
            f'<video controls loop muted autoplay playsinline preload="auto"><source src="{src}" type="{mime}"></video>'
        )
    else:
        body = f'<a href="{src}"><img src="{src}" alt="{escape(fig.caption, quote=True)}"></a>'
    cls = ' class="wide"' if fig.wide else ""
    return f"<figure{cls}>{body}<figcaption>{cap}</figcaption></figure>"


def _section_html(sec: Section) -> str:
    out = [f'<section id="{escape(sec.key, quote=True)}"><h2>{escape(sec.title)}</h2>']
    if sec.text:
        out.append(f"<p>{escape(sec.text)}</p>")
    out.extend(f'<div class="note">{escape(n)}</div>' for n in sec.notes)
    if sec.table:
        out.append(_table(sec.table))
    if sec.figures:
        out.append('<div class="grid">' + "".join(_figure_html(f) for f in sec.figures) + "</div>")
    out.append("</section>")
    return "".join(out)


def _header_rows(ctx: ReportContext, description: str) -> dict[str, list[tuple[str, Any]]]:
    """The header's tables: run, configuration, versions, metrics, timings, report build."""
    import numpy as np

    blocks: dict[str, list[tuple[str, Any]]] = {}
    data = ctx.data
    if data is not None:
        run = data.run
        blocks["Run"] = [
            ("tracker", f"{data.tracker}: {description}"),
            ("status", run.get("status")),
            ("folder", str(data.run_dir.resolve())),
            ("started", run.get("started")),
            ("finished", run.get("finished")),
            ("elapsed", f"{run['elapsed_s']:.2f} s" if isinstance(run.get("elapsed_s"), (int, float)) else "-"),
            ("frames", run.get("frames", len(data.frames))),
            ("device", run.get("device", (run.get("summary") or {}).get("device", "-"))),
            ("seed", run.get("seed", "-")),
            ("ground truth", str(data.groundtruth_path) if data.groundtruth_path else "none"),
        ]
        cfg = data.config
        rows: list[tuple[str, Any]] = []
        for k, v in cfg.items():
            if isinstance(v, dict):
                rows.extend((f"{k}.{kk}", _fmt(vv)) for kk, vv in v.items())
            else:
                rows.append((k, _fmt(v)))
        blocks["Configuration"] = rows
        versions = dict(run.get("versions") or {})
        blocks["Versions (tracking run)"] = [(k, v) for k, v in versions.items()]
        summary = run.get("summary") or {}
        metrics = []
        if isinstance(summary, dict):
            for k, v in summary.items():
                if isinstance(v, dict):
                    for kk, vv in v.items():
                        is_err = isinstance(vv, float) and "error" in kk
                        metrics.append((f"{k}.{kk}", f"{100 * vv:.2f} cm" if is_err else _fmt(vv)))
                else:
                    metrics.append((k, _fmt(v)))
        blocks["Metrics"] = metrics
        timings = run.get("timings") or {}
        blocks["Timings (per frame)"] = [
            (
                k,
                f"median {v.get('median_ms', np.nan):.2f} ms, mean {v.get('mean_ms', np.nan):.2f} ms, "
                f"total {v.get('total_s', np.nan):.2f} s",
            )
            for k, v in timings.items()
            if isinstance(v, dict)
        ]
    report_rows: list[tuple[str, Any]] = [("renderer", ctx.renderer or "-"), ("python", platform.python_version())]
    for mod in ("pyvista", "vtk", "matplotlib", "cv2"):
        report_rows.append((mod, _module_version(mod)))
    report_rows.extend((f"time: {k}", f"{v:.2f} s") for k, v in ctx.timings.items())
    blocks["Report build"] = report_rows
    return blocks


def _module_version(name: str) -> str:
    import sys

    mod = sys.modules.get(name)
    if mod is None:
        return "not used"
    if name == "vtk":
        try:
            return str(mod.vtkVersion.GetVTKVersion())
        except AttributeError:
            pass
    return str(getattr(mod, "__version__", "?"))


def write_index(ctx: ReportContext, sections: list[Section], description: str = "") -> Path:
    """Write ``index.html`` into the report folder and return its path."""
    data = ctx.data
    if data is not None:
        title = f"wptrack report: {data.run_dir.resolve().name}"
        sub = f"{data.tracker} tracker, {len(data.frames)} frames, status {data.run.get('status')}"
    else:
        title = "wptrack report: sigma_m sweep"
        sub = str(ctx.sweep["path"]) if ctx.sweep else ""
    blocks = _header_rows(ctx, description)
    cards = "".join(f"<div><h3>{escape(name)}</h3>{_table(rows)}</div>" for name, rows in blocks.items() if rows)
    notes = list(ctx.notes) + (list(data.notes) if data is not None else [])
    nav = " ".join(f'<a href="#{escape(s.key, quote=True)}">{escape(s.title)}</a>' for s in sections)
    raw = ""
    if data is not None:
        raw = (
            "<details><summary>run.json</summary><pre>"
            + escape(json.dumps(data.run, indent=2, default=str))
            + "</pre></details>"
        )
    page = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{escape(title)}</title><style>{_CSS}</style></head><body>"
        f"<header><h1>{escape(title)}</h1><p>{escape(sub)}</p></header><main>"
        f"<nav>{nav}</nav>"
        + "".join(f'<div class="note">{escape(n)}</div>' for n in notes)
        + f'<section id="summary"><h2>Summary</h2><div class="cards">{cards}</div>{raw}</section>'
        + "".join(_section_html(s) for s in sections)
        + "</main></body></html>\n"
    )
    path = ctx.out_dir / INDEX_FILE
    atomic_write_text(path, page)
    return path
