"""Self-contained HTML reports: a run's ``report.html`` and a sweep's ``report/report.html``.

One file each that opens in any browser with no server and nothing fetched: figures are
embedded as base64 PNG, the style is inline, there is no script. A run's page holds its
figures, its metrics (field errors, reconstruction scores, timings), its capture and
configuration; a sweep's holds the quality plot and its numbers, every run's row with a
link to the run's own page, the timings and the configuration the runs share.
"""

from __future__ import annotations

import base64
import html
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import msgspec

from nlosfw.common import yaml_safe
from nlosfw.common.config import Scalar
from nlosfw.common.text import MAX_SHOWN, href, html_block, html_text, shortened
from nlosfw.evaluation.reference import REFERENCE, REFERENCE_TITLE
from nlosfw.pipeline.metrics import RunMetrics
from nlosfw.report.inputs import figure_inside, inside
from nlosfw.report.quality import QualityTable, parse_overrides
from nlosfw.report.records import RunRecord
from nlosfw.report.tables import format_cell
from nlosfw.report.titles import run_title

_STYLE = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1400px;
       padding: 0 1em; color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 1.8em;
  border-bottom: 1px solid #ccc; } h3 { font-size: 1em; }
table { border-collapse: collapse; margin: 0.6em 0 1.2em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f2f2f2; } td:first-child, th:first-child { text-align: left; }
figure { margin: 1em 0 2em; } figure img { max-width: 100%; height: auto;
  border: 1px solid #ddd; } figcaption { color: #555; font-size: 0.9em; }
pre { background: #f7f7f7; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
.meta { color: #555; } .muted { color: #888; } .scroll { overflow-x: auto; }
.views { display: flex; flex-wrap: wrap; gap: 0.8em; align-items: flex-start; }
.views figure { margin: 0.4em 0; flex: 1 1 22em; max-width: 32em; }
.views figure.wide { flex: 2 1 40em; max-width: none; }
"""


#: The most characters of a block of text (a configuration) a page shows.
MAX_BLOCK = 64 * MAX_SHOWN


def page(title: str, sections: Sequence[str]) -> str:
    """A whole HTML document: ``title`` as its heading, then ``sections`` (HTML)."""
    body = "\n".join(sections)
    return (f"<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
            f"<title>{html_text(title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n"
            f"<h1>{html_text(title)}</h1>\n{body}\n</body>\n</html>\n")


def table(header: Sequence[str], rows: Sequence[Sequence[Scalar]]) -> str:
    """An HTML table; cells are escaped (control characters made visible), None is empty,
    floats have 4 significant digits."""
    head = "".join(f"<th>{html_text(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html_text(format_cell(c))}</td>" for c in row)
                   + "</tr>"
                   for row in rows)
    return (f"<div class=\"scroll\"><table>\n<thead><tr>{head}</tr></thead>\n<tbody>{body}"
            "</tbody>\n</table></div>")


def png_figure(data: bytes, caption: str, wide: bool = False) -> str:
    """A PNG embedded as a data URI, with its caption (``wide``: twice a view's width)."""
    encoded = base64.b64encode(data).decode("ascii")
    text = html_text(caption)
    kind = ' class="wide"' if wide else ""
    return (f"<figure{kind}><img src=\"data:image/png;base64,{encoded}\" alt=\"{text}\">"
            f"<figcaption>{text}</figcaption></figure>")


def preformatted(text: str, summary: str | None = None) -> str:
    """Text as is (escaped, control characters made visible, at most :data:`MAX_BLOCK`
    characters of it), folded under ``summary`` when given."""
    block = f"<pre>{html_block(shortened(text, MAX_BLOCK))}</pre>"
    return block if summary is None else (
        f"<details><summary>{html_text(summary)}</summary>{block}</details>")


def _section(title: str, *parts: str) -> str:
    return f"<h2>{html_text(title)}</h2>\n" + "\n".join(parts)


def _timings(metrics: RunMetrics) -> dict[str, float]:
    return {k: v for k, v in msgspec.structs.asdict(metrics.timings).items() if v is not None}


#: Figures of a run in the order its page shows them, with their captions.
_FIGURES = (
    ("reconstructions.png", "every field imaged from all frequencies, side by side"),
    ("reconstructions_f*.png", "images from one frequency alone"),
    ("fields_f*.png", "the phasor fields on the relay wall at one frequency"),
    ("loss.png", "training loss"),
)


def run_report(run_dir: Path, metrics: RunMetrics, config: Mapping[str, object],
               overrides: Sequence[str] = ()) -> str:
    """The HTML of a run's ``report.html`` (figures read from ``run_dir/figures``)."""
    info = metrics.run
    title = f"nlosfw run: {run_title(info)}"
    meta = (f"<p class=\"meta\">status <b>{html_text(metrics.status)}</b>"
            f"{' after ' + html_text(info.stopped_after) if info.stopped_after else ''}"
            f" · started {html_text(info.started)} · nlosfw {html_text(info.nlosfw_version)}"
            f" · {html_text(info.dir)}</p>")
    if overrides:
        meta += f"<p class=\"meta\">overrides: <code>{html_text(' '.join(overrides))}</code></p>"
    sections = [meta, _run_views(run_dir, metrics), *_run_metrics(metrics),
                _run_figures(run_dir),
                _section("Timings (s)", table(["stage", "seconds"], list(_timings(metrics)
                                                                         .items()))),
                _run_inputs(metrics),
                _section("Configuration", preformatted(
                    yaml_safe.dump(dict(config)), "the resolved configuration (config.yaml)")),
                _section("Files", _files(run_dir))]
    return page(title, sections)


def _run_metrics(metrics: RunMetrics) -> list[str]:
    out = []
    if metrics.reconstruction is not None:
        rec = metrics.reconstruction
        if list(rec.sources) == ["true"]:  # model=none: the capture alone, nothing to score
            seconds = rec.sources["true"].seconds
            return [_section("Reconstruction", (
                f"<p>The capture imaged with <code>{html_text(rec.imager)}</code> on "
                f"{len(rec.depths)} depth planes from {min(rec.depths):.3g} to "
                f"{max(rec.depths):.3g} m" + ("" if seconds is None else f" in {seconds:.3g} s")
                + "; no field model (model=none), so no scores.</p>"))]
        rows = [[s, v.ssim, v.psnr, v.rmse, v.seconds] for s, v in rec.sources.items()]
        parts = [f"<p>Max-intensity image of each field against the true field's, imager "
                 f"<code>{html_text(rec.imager)}</code>, {len(rec.depths)} depth planes "
                 f"from {min(rec.depths):.3g} to {max(rec.depths):.3g} m.</p>",
                 table(["source", "SSIM", "PSNR (dB)", "RMSE", "seconds"], rows)]
        for index, single in rec.single_frequency.items():
            parts.append(f"<h3>From frequency {index} alone: f = {single.frequency:.4g} "
                         f"cycles/m ({html_text(single.split)})</h3>")
            parts.append(table(["source", "SSIM", "PSNR (dB)", "RMSE"],
                               [[s, v.ssim, v.psnr, v.rmse] for s, v in single.sources.items()]))
        out.append(_section("Reconstructions", *parts))
    if metrics.field:
        rows = []
        for source, entry in metrics.field.items():
            splits = entry.splits.by_set() if entry.splits is not None else {}
            gain = None if entry.denoising is None else entry.denoising.gain_db
            rows.append([source, entry.plugin, entry.n_parameters, entry.fit.seconds,
                         entry.predict_seconds,
                         *(splits[k].nmse_db if k in splits else None
                           for k in ("heldout_pixels", "heldout_frequencies", "all")), gain])
        out.append(_section(
            "Field models",
            "<p>Complex field error against the true field, NMSE (dB, lower is better).</p>",
            table(["source", "plugin", "parameters", "fit (s)", "predict (s)",
                   "held-out pixels", "held-out frequencies", "all samples",
                   "noise removed (dB)"], rows)))
    return out


def _run_views(run_dir: Path, metrics: RunMetrics) -> str:
    """The views of every imaged source side by side (front view, depth map, depth slices),
    the reference picture's (the measured histograms at native bins, when the run made
    one), then the capture's time profile with the depth range marked; nothing without
    them."""
    folder = run_dir / "figures"
    imager = metrics.run.imager or "?"
    sources = list(metrics.reconstruction.sources) if metrics.reconstruction else []
    rows = []
    for source in sources:
        figures = _view_figures(run_dir, source)
        if figures:
            name = "the capture" if sources == ["true"] else source
            rows.append(f"<h3>{html_text(name)} · imager {html_text(imager)}</h3>"
                        f"<div class=\"views\">{''.join(figures)}</div>")
    reference = _view_figures(run_dir, REFERENCE)
    if reference:
        rows.append(f"<h3>{html_text(REFERENCE_TITLE)} · imager {html_text(imager)}</h3>"
                    "<p class=\"muted\">The whole capture's histograms at their native bin "
                    "width (every DFT bin), imaged as the authors' code images them, on the "
                    "same planes: the picture to compare the sources with. Not scored: every "
                    "scored source is imaged from the same band.</p>"
                    f"<div class=\"views\">{''.join(reference)}</div>")
    profile = figure_inside(folder / "time_profile.png", run_dir)
    if profile is not None:
        rows.append(png_figure(profile, "time_profile.png: the capture's "
                               "histograms summed over the wall, the planes' depth range "
                               "shaded"))
    return _section("Views", *rows) if rows else ""


def _view_figures(run_dir: Path, source: str) -> list[str]:
    """The front view, depth map and depth slices of ``source`` that ``run_dir/figures``
    holds (regular files inside ``run_dir``)."""
    folder = run_dir / "figures"
    shown = [(folder / f"{view}_{source}.png", caption) for view, caption in (
        ("front", "front view over the planes' depths"),
        ("depth", "depth map (grey: no signal)"),
        ("slices", "depth slices"))]
    return [png_figure(data, f"{path.name}: {caption}", wide=path.name.startswith("slices_"))
            for path, caption in shown if (data := figure_inside(path, run_dir)) is not None]


def _run_figures(run_dir: Path) -> str:
    folder = run_dir / "figures"
    parts = []
    for pattern, caption in _FIGURES:
        for path in sorted(folder.glob(pattern)) if folder.is_dir() else []:
            data = figure_inside(path, run_dir)
            if data is not None:
                parts.append(png_figure(data, f"{path.name}: {caption}"))
    if not parts and folder.is_dir() and any(folder.glob("*.png")):
        return ""  # the views are all there is (model=none)
    if not parts:
        parts = ["<p class=\"muted\">No figures (figures.enabled=false, or the run stopped "
                 "before it imaged).</p>"]
    return _section("Figures", *parts)


def _run_inputs(metrics: RunMetrics) -> str:
    rows: list[list[Scalar]] = []
    if metrics.capture is not None:
        c = metrics.capture
        origin: list[Scalar] = (["simulator", c.simulator] if c.path is None else
                                ["format", c.format])
        rows += [["capture", c.source if c.path is None else f"file {c.path}"], origin,
                 ["shape (t, x, y)", " × ".join(map(str, c.shape))],
                 ["kind", c.kind.value], ["bin width (m)", c.delta_t],
                 ["noise", None if c.noise is None else str(c.noise)]]
    if metrics.transform is not None:
        t = metrics.transform
        rows += [["transform", t.name], ["frequencies", t.n_frequencies],
                 ["band (cycles/m)", f"{t.frequency_band[0]:.4g} to {t.frequency_band[1]:.4g}"],
                 ["wall grid (y, x)", " × ".join(map(str, t.grid))]]
    return _section("Capture and phasor field", table(["", ""], rows))


def _files(run_dir: Path) -> str:
    rows = []
    for path in sorted(p for p in run_dir.rglob("*") if inside(p, run_dir)):
        rel = path.relative_to(run_dir).as_posix()
        if rel.startswith(".") or "/." in rel or rel == "report.html":
            continue
        rows.append(f"<tr><td><a href=\"{html.escape(href(rel))}\">{html_text(rel)}</a></td>"
                    f"<td>{path.stat().st_size / 1e6:.2f}</td></tr>")
    return ("<table>\n<thead><tr><th>file</th><th>MB</th></tr></thead>\n<tbody>"
            + "".join(rows) + "</tbody>\n</table>")


def sweep_report(root: Path, out_dir: Path, records: Sequence[RunRecord],
                 rows: Sequence[Mapping[str, str]], figure: bytes,
                 tables: Sequence[QualityTable]) -> str:
    """The HTML of a sweep's ``report/report.html``: ``figure`` (the quality plot's PNG) and
    its ``tables``, every run's ``rows`` (report.csv's) with a link to the run's page, the
    timings and the configuration (``records``: the runs' :class:`RunRecord`)."""
    sections = [f"<p class=\"meta\">{len(records)} runs under {html_text(root)}</p>",
                _section("Quality against the swept parameter",
                         png_figure(figure, "quality against the swept parameter (report.png)"),
                         *(f"<h3>{html_text(t.heading)}</h3>" + table(t.header, t.rows)
                           for t in tables))]
    columns = list(rows[0]) if rows else []
    linked = []
    for record, row in zip(records, rows, strict=True):
        page_path = root / record.name / "report.html"
        link = (f"<a href=\"{html.escape(href(_relative(page_path, out_dir)))}\">"
                f"{html_text(record.name)}</a>" if inside(page_path, root)
                else html_text(record.name))
        cells = "".join(f"<td>{html_text(row[c])}</td>" for c in columns[1:])
        linked.append(f"<tr><td>{link}</td>{cells}</tr>")
    head = "".join(f"<th>{html_text(c)}</th>" for c in columns)
    sections.append(_section("Every run", "<div class=\"scroll\"><table>\n<thead><tr>" + head
                             + "</tr></thead>\n<tbody>" + "".join(linked)
                             + "</tbody>\n</table></div>"))
    stages = ["capture", "transform", "fit", "predict", "reconstruct", "report", "total"]
    sections.append(_section("Timings (s)", table(
        ["run", *stages], [[r.name, *(_timings(r.metrics).get(s) for s in stages)]
                           for r in records])))
    sections.append(_section("Configuration", *_sweep_config(root, records)))
    return page(f"nlosfw sweep report: {root.name}", sections)


def _relative(path: Path, start: Path) -> str:
    return Path(os.path.relpath(path, start)).as_posix()


def _sweep_config(root: Path, records: Sequence[RunRecord]) -> list[str]:
    by_run = [parse_overrides(r.overrides) for r in records]
    keys = list(dict.fromkeys(k for run in by_run for k in run))
    swept = [k for k in keys if len({run.get(k) for run in by_run}) > 1]
    common = [f"{k}={by_run[0][k]}" for k in keys if k not in swept
              and all(k in run for run in by_run)]
    parts = [table(["swept", "values"], [[k, ", ".join(dict.fromkeys(
        run.get(k, "(default)") for run in by_run))] for k in swept]),
        f"<p>Overrides every run shares: <code>{html_text(' '.join(common) or '(none)')}"
        "</code></p>"]
    if records and records[0].config:
        parts.append(preformatted(yaml_safe.dump(dict(records[0].config)),
                                  f"the resolved configuration of {records[0].name}"))
    return parts
