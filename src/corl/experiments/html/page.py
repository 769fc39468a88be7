"""The markup of ``corl report``: one HTML page per run, with inline CSS and no external reference.

Every text taken from the store goes through :func:`html.escape`. Images and the video arrive as
``data:`` URIs (see :mod:`corl.experiments.html.report`). A tiny inline script records, once the
page has loaded, how many images decoded (``data-images-loaded`` / ``data-images-total`` on
``<body>``) and the video's frame size (``data-video-width``), so a headless browser can check the
page without a person looking at it.
"""

from __future__ import annotations

import json
import math
from datetime import datetime, timezone
from html import escape
from pathlib import Path
from typing import Any, Iterable

__all__ = ["render_page", "render_index"]

_CSS = """
:root { --ink: #1d2330; --muted: #5b6475; --line: #dde1e8; --bg: #f6f7f9; --accent: #2457a6;
        --fail: #fdecec; --failink: #b3261e; --best: #fff4cc; }
* { box-sizing: border-box; }
body { margin: 0; background: var(--bg); color: var(--ink); line-height: 1.45;
       font: 15px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif; }
main { max-width: 1180px; margin: 0 auto; padding: 24px 28px 48px; }
header h1 { font-size: 24px; margin: 0 0 4px; }
header p { margin: 0; color: var(--muted); }
section { background: #fff; border: 1px solid var(--line); border-radius: 8px; padding: 16px 20px;
          margin-top: 18px; }
h2 { font-size: 17px; margin: 0 0 12px; }
h3 { font-size: 14px; margin: 0 0 6px; color: var(--muted); font-weight: 600; }
.cards { display: grid; grid-template-columns: repeat(auto-fit, minmax(170px, 1fr)); gap: 12px;
         margin-top: 18px; }
.card { background: #fff; border: 1px solid var(--line); border-radius: 8px; padding: 10px 14px; }
.card .k { color: var(--muted); font-size: 12px; text-transform: uppercase; letter-spacing: .04em; }
.card .v { font-size: 20px; font-weight: 600; font-variant-numeric: tabular-nums; }
.card .s { color: var(--muted); font-size: 12px; }
.cols { display: grid; grid-template-columns: repeat(auto-fit, minmax(340px, 1fr)); gap: 20px; }
table { border-collapse: collapse; width: 100%; font-size: 13px; }
th, td { text-align: left; padding: 4px 8px; border-bottom: 1px solid var(--line); vertical-align: top; }
th { color: var(--muted); font-weight: 600; }
td.num, th.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td code, .kv td:first-child { font-family: ui-monospace, "DejaVu Sans Mono", monospace; font-size: 12px; }
.kv td:first-child { color: var(--muted); white-space: nowrap; }
.scroll { max-height: 440px; overflow: auto; border: 1px solid var(--line); border-radius: 6px; }
.scroll thead th { position: sticky; top: 0; background: #f0f2f5; }
.trials tr.fail td { background: var(--fail); }
.trials tr.fail td.ok { color: var(--failink); font-weight: 600; }
.trials tr.best td { background: var(--best); font-weight: 600; }
.trials tr.learned td { font-weight: 600; }
.trials tr.learned td:first-child { box-shadow: inset 4px 0 0 #2e8b57; }
.trials tr.pending td { color: var(--muted); font-style: italic; }
figure { margin: 0; }
figure img { width: 100%; height: auto; border: 1px solid var(--line); border-radius: 6px; background: #fff; }
figcaption { color: var(--muted); font-size: 13px; margin-top: 6px; }
.figs { display: grid; grid-template-columns: repeat(auto-fit, minmax(420px, 1fr)); gap: 20px; }
.wide { max-width: 980px; }
video, .video img { max-width: 100%; border-radius: 6px; background: #000; }
.notes { background: #fff8e6; border-color: #f0d58c; }
.notes li { margin: 2px 0; }
.changed { color: var(--failink); }
.legend { color: var(--muted); font-size: 13px; margin: 8px 0 0; }
footer { color: var(--muted); font-size: 12px; margin-top: 24px; }
"""

_SCRIPT = """
window.addEventListener("load", function () {
  var imgs = Array.prototype.slice.call(document.images);
  var ok = imgs.filter(function (im) { return im.complete && im.naturalWidth > 0; });
  document.body.setAttribute("data-images-total", String(imgs.length));
  document.body.setAttribute("data-images-loaded", String(ok.length));
  var v = document.querySelector("video");
  function size() { document.body.setAttribute("data-video-width", String(v.videoWidth)); }
  if (v) { if (v.readyState >= 1) { size(); } else { v.addEventListener("loadedmetadata", size); } }
});
"""


def _fmt(value: Any, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; '-' for None and NaN."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int,)):
        return str(value)
    try:
        x = float(value)
    except (TypeError, ValueError):
        return str(value)
    return "-" if math.isnan(x) else f"{x:.{digits}g}"


def _fmt_J(value: Any) -> str:
    """J in one format down the table's column (it spans decades): 4 significant digits, exponent form,
    as the dashboard of corl serve writes it; '-' for None and NaN."""
    return "-" if value is None or math.isnan(float(value)) else f"{float(value):.3e}"


def _kv_table(rows: Iterable[tuple[str, Any]], *, css: str = "kv") -> str:
    body = "".join(f"<tr><td>{escape(str(k))}</td><td>{escape(_plain(v))}</td></tr>" for k, v in rows)
    return f'<table class="{css}"><tbody>{body}</tbody></table>'


def _plain(value: Any) -> str:
    if isinstance(value, float):
        return _fmt(value, 6)
    if isinstance(value, (dict, list)):
        return json.dumps(value)
    return "-" if value is None else str(value)


def _flatten(config: dict, prefix: str = "") -> list[tuple[str, Any]]:
    """``{"solver": {"tol": 1}}`` -> ``[("solver.tol", 1)]``."""
    rows = []
    for key, value in config.items():
        name = f"{prefix}{key}"
        rows += _flatten(value, name + ".") if isinstance(value, dict) and value else [(name, value)]
    return rows


def _cards(report) -> str:
    records, info = report.records, report.info
    told = [r for r in records if r.outcome is not None]
    failures = sum(not r.outcome.success for r in told)
    cards = [("trials", str(len(records)), f"{len(told)} told, {len(records) - len(told)} pending"),
             ("failures", str(failures), f"{failures / len(told):.1%} of told trials" if told else "")]
    if report.best_index is not None:
        best = records[report.best_index]
        theta = ", ".join(_fmt(v) for v in best.proposal.theta)
        cards.append(("best observed reading", _fmt(best.outcome.return_, 5), f"trial {best.index}, θ ({theta})"))
    else:
        cards.append(("best observed reading", "-", "no successful trial yet"))
    J0 = report.J[0] if len(report.J) else math.nan
    if report.learned_index is not None:
        learned = records[report.learned_index]
        note = f"trial {learned.index}" + ("" if math.isnan(J0) else
                                           f", J {_fmt(J0)} → {_fmt(report.J[report.learned_index])}")
        cards.append(("learner's best (w*, θ*): return", _fmt(learned.outcome.return_, 5), note))
    elif report.best_index is not None and not math.isnan(J0):
        cards.append(("J: first trial → best", f"{_fmt(J0)} → {_fmt(report.J[report.best_index])}",
                      "analytic cost of w (Eq. 7)"))
    cards.append(("status", info.status.value, f"{info.method}, seed {info.seed}"))
    return '<div class="cards">' + "".join(
        f'<div class="card"><div class="k">{escape(k)}</div><div class="v">{escape(v)}</div>'
        f'<div class="s">{escape(s)}</div></div>' for k, v, s in cards) + "</div>"


def _configuration(report) -> str:
    info = report.info
    config = dict(info.config)
    learner = config.pop("learner", None)
    run_rows = [("run", info.id), ("task", info.task), ("task spec", config.pop("task_spec", "-")),
                ("method", info.method), ("seed", info.seed), ("status", info.status.value),
                ("created (UTC)", info.created), ("store", str(report.store_path)),
                ("trials stored / told", f"{info.n_trials} / {info.n_told}"),
                ("learner rebuilt by replay", "yes" if report.replayed else "no")]
    run_rows += [(k, v) for k, v in config.items() if k != "task_name"]
    right = ("<h3>Learner configuration</h3>" + _kv_table(_flatten(learner))) if isinstance(learner, dict) else \
        "<h3>Learner configuration</h3><p>Not stored with this run (the method has no configuration object).</p>"
    return ('<section id="configuration"><h2>Configuration</h2><div class="cols">'
            f"<div><h3>Run</h3>{_kv_table(run_rows)}</div><div>{right}</div></div></section>")


def _versions(report) -> str:
    from corl.versions import library_versions

    recorded, now = report.info.versions, library_versions()
    rows = []
    for key in sorted(recorded):
        current = now.get(key, "-")
        mark = ' class="changed"' if current != recorded[key] else ""
        rows.append(f"<tr><td><code>{escape(key)}</code></td><td>{escape(str(recorded[key]))}</td>"
                    f"<td{mark}>{escape(str(current))}</td></tr>")
    if not rows:
        return '<section id="versions"><h2>Software</h2><p>No versions were recorded with this run.</p></section>'
    return ('<section id="versions"><h2>Software</h2><table><thead><tr><th>library</th>'
            '<th>recorded with the run</th><th>this report (red: differs)</th></tr></thead><tbody>'
            + "".join(rows) + "</tbody></table></section>")


def _figure(title: str, caption: str, uri: str, css: str = "") -> str:
    heading = f"<h3>{escape(title)}</h3>" if title else ""
    return (f'<figure class="{css}">{heading}<img alt="{escape(title or caption)}" src="{uri}">'
            f"<figcaption>{escape(caption)}</figcaption></figure>")


def _figures(report) -> str:
    parts = []
    if report.curves is not None:
        parts.append('<section id="curves"><h2>Learning curves</h2>'
                     f'{_figure("", *report.curves, css="wide")}</section>')
    figs = [_figure(*f) for f in report.figures]
    if report.return_map is not None:
        figs.append(_figure("Return map (Fig. 2c)", *report.return_map))
    if figs:
        heading = "Return map" if report.return_map is not None and not report.figures else (
            "Motion optimization and return map" if report.return_map is not None else "Motion optimization")
        parts.append(f'<section id="return-map"><h2>{heading}</h2><div class="figs">{"".join(figs)}</div></section>')
    return "".join(parts)


def _video(report) -> str:
    if report.video is None:
        return ""
    mime, uri, origin = report.video
    media = (f'<video controls loop muted playsinline preload="metadata"><source src="{uri}" type="{mime}">'
             "Your browser cannot play this MP4.</video>") if mime.startswith("video/") else \
        f'<div class="video"><img alt="video" src="{uri}"></div>'
    return (f'<section id="video"><h2>Demonstration (left) and learned motion (right)</h2>{media}'
            f'<p class="legend">Video: {escape(origin)}.</p></section>')


def _trials(report) -> str:
    labels = report.theta_labels
    head = "".join(f'<th class="num" title="{escape(label)}">θ{k + 1}</th>' for k, label in enumerate(labels))
    rows = []
    for i, record in enumerate(report.records):
        p, o = record.proposal, record.outcome
        if o is None:
            css, ok, ret = "pending", "pending", "-"
        else:
            css = "" if o.success else "fail"
            ok, ret = ("yes" if o.success else "FAILURE"), _fmt(o.return_, 6)
        if i == report.best_index:
            css = "best"
        if i == report.learned_index:
            css += " learned"
        theta = "".join(f'<td class="num">{_fmt(v, 5)}</td>' for v in p.theta)
        rows.append(f'<tr class="{css}"><td class="num">{p.index}</td><td class="num">{p.round}</td>'
                    f"<td>{escape(str(p.step))}</td>{theta}<td class=\"ok\">{ok}</td>"
                    f'<td class="num">{ret}</td><td class="num">{_fmt_J(report.J[i])}</td></tr>')
    legend = "; ".join(f"θ{k + 1}: {escape(label)}" for k, label in enumerate(labels))
    return (f'<section id="trials"><h2>Trials ({len(rows)})</h2><div class="scroll">'
            '<table class="trials"><thead><tr><th class="num">#</th><th class="num">round</th><th>step</th>'
            f'{head}<th>success</th><th class="num">return R</th><th class="num">J(w)</th></tr></thead>'
            f'<tbody>{"".join(rows)}</tbody></table></div>'
            f'<p class="legend">{legend}. Yellow: the best observed reading; green edge: the learner\'s best '
            "(w*, θ*), what it returned; red: failures (no return).</p></section>")


def _notes(report) -> str:
    if not report.notes:
        return ""
    items = "".join(f"<li>{escape(note)}</li>" for note in report.notes)
    return f'<section class="notes"><h2>Not shown</h2><ul>{items}</ul></section>'


def _document(title: str, body: str) -> str:
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{escape(title)}</title><style>{_CSS}</style></head>\n"
            f"<body><main>{body}</main><script>{_SCRIPT}</script></body></html>\n")


def _footer() -> str:
    from corl.versions import library_versions

    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return f"<footer>Written by corl {escape(library_versions()['corl'])} (corl report) on {stamp}.</footer>"


def render_page(report) -> str:
    """The self-contained HTML page of one :class:`~corl.experiments.html.report.RunReport`."""
    info = report.info
    title = f"Run {info.id}: {info.method} on {info.task} (seed {info.seed})"
    header = (f"<header><h1>{escape(title)}</h1><p>Store <code>{escape(str(report.store_path))}</code>, "
              f"created {escape(info.created)}</p></header>")
    body = (header + _cards(report) + _notes(report) + _configuration(report) + _figures(report)
            + _video(report) + _trials(report) + _versions(report) + _footer())
    return _document(title, body)


def render_index(infos, store: Path) -> str:
    """A page listing the runs with links to their pages ``run_<id>.html`` in the same folder."""
    rows = "".join(f'<tr><td class="num"><a href="run_{i.id}.html">{i.id}</a></td><td>{escape(i.task)}</td>'
                   f"<td>{escape(i.method)}</td><td class=\"num\">{escape(str(i.seed))}</td>"
                   f'<td class="num">{i.n_trials}</td><td>{escape(i.status.value)}</td>'
                   f"<td>{escape(i.created)}</td></tr>" for i in infos)
    body = (f"<header><h1>Runs of {escape(Path(store).name)}</h1><p><code>{escape(str(store))}</code></p></header>"
            '<section><table><thead><tr><th class="num">run</th><th>task</th><th>method</th><th class="num">seed'
            '</th><th class="num">trials</th><th>status</th><th>created</th></tr></thead>'
            f"<tbody>{rows}</tbody></table></section>" + _footer())
    return _document(f"corl runs of {Path(store).name}", body)
