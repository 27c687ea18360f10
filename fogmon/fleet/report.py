"""The fleet report of `fogmon batch` (``write_report``, FLEET.html): one page readable at a glance,
with FLEET-trends.png (N and B of every recording with their intervals, per gyro, in
recording order) and FLEET.csv (the per-recording table) beside it.

A gyro is what the recordings table's ``gyro`` column names (fogmon.fleet.identity: a
serial number, else the sensor name within its folder, else the recording alone, or
`--group-by`; never the folder alone); its recordings are taken in name order
(date-stamped names sort in time). A gyro's N or B "changed" when its latest recording's whole-record estimate differs
from its first's by more than ``Z_CHANGED`` combined standard errors (each standard error
is half the 68.3 % interval; both estimates identifiable): |z| > 3 happens by chance with
probability 0.27 % for one coefficient of one gyro. A run is "outside its model" when a
sensor model was given and its explain score (before fitting effects) exceeds
``SCORE_OUTSIDE`` (no null record of validation/calibration.py exceeded 1.5 before
fitting effects: 0 of 200, docs/explain.md "The null sweep")."""
from __future__ import annotations

import html
import math
import os
from collections.abc import Mapping

import numpy as np

from fogmon.errors import render_names
from fogmon.outputs import written

Z_CHANGED = 3.0
SCORE_OUTSIDE = 1.5
TREND_COEFS = (("N_dpsh", "N (deg/sqrt(h))"), ("B_dph", "B (deg/h)"))


def gyro_of(row: dict) -> str:
    """The gyro of a recordings-table row (its ``gyro`` column, fleet.identity; a table
    without it: the recording alone)."""
    return row.get("gyro") or os.path.basename(os.path.normpath(row["recording"]))


def by_gyro(rows: list[dict]) -> dict[str, list[dict]]:
    """The analysed rows per gyro (``gyro_of``); a gyro whose rows name several axes is
    one gyro per axis, labelled "<gyro> axis <name>"."""
    groups: dict[str, list[dict]] = {}
    for r in rows:
        if not r["error"]:
            groups.setdefault(gyro_of(r), []).append(r)
    out: dict[str, list[dict]] = {}
    for g, rs in groups.items():
        if len({r.get("axis") for r in rs}) == 1:
            out[g] = rs
            continue
        for r in rs:
            out.setdefault(f"{g} axis {r['axis']}", []).append(r)
    return out


def changes(rows: list[dict]) -> list[dict]:
    """Per gyro (``by_gyro``) with at least two analysed recordings and per coefficient
    of TREND_COEFS: first and latest estimate, z and whether |z| > Z_CHANGED."""
    out = []
    for g, rs in sorted(by_gyro(rows).items()):
        rs = sorted(rs, key=lambda r: r["recording"])
        if len(rs) < 2:
            continue
        a, b = rs[0], rs[-1]
        for c, label in TREND_COEFS:
            ok = a[f"identifiable_{c}"] and b[f"identifiable_{c}"]
            se = math.hypot((a[f"{c}_hi"] - a[f"{c}_lo"]) / 2, (b[f"{c}_hi"] - b[f"{c}_lo"]) / 2)
            z = (b[c] - a[c]) / se if ok and se > 0 else float("nan")
            out.append({"gyro": g, "coefficient": label, "first": a["recording"], "latest": b["recording"],
                        "first_value": a[c], "latest_value": b[c], "z": z, "changed": bool(abs(z) > Z_CHANGED),
                        "tested": "yes" if ok else "no: not identifiable in both"})
    return out


def gyro_summary(rows: list[dict]) -> str:
    """E.g. "4 recordings of 3 gyros (gyro named by serial: 2, sensor + folder: 2)"."""
    counts: dict[str, int] = {}
    for r in rows:
        key = r.get("gyro_named_by") or "recording"
        counts[key] = counts.get(key, 0) + 1
    named = ", ".join(f"{k}: {n}" for k, n in sorted(counts.items()))
    return f"{len(rows)} recordings of {len({gyro_of(r) for r in rows})} gyros (gyro named by {named})"


def _trend_png(rows: list[dict], path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    groups = by_gyro(rows)
    fig, axes = plt.subplots(len(TREND_COEFS), 1, figsize=(10, 3.2 * len(TREND_COEFS)), sharex=True)
    for ax, (c, label) in zip(np.atleast_1d(axes), TREND_COEFS, strict=True):
        for g, rs in sorted(groups.items()):
            rs = sorted(rs, key=lambda r: r["recording"])
            x = np.arange(len(rs))
            v = np.array([r[c] for r in rs], float)
            ident = np.array([r[f"identifiable_{c}"] for r in rs], bool)
            lo, hi = np.array([r[f"{c}_lo"] for r in rs], float), np.array([r[f"{c}_hi"] for r in rs], float)
            line = ax.errorbar(x[ident], v[ident], yerr=[v[ident] - lo[ident], hi[ident] - v[ident]], marker="o",
                               capsize=3, label=g)
            if (~ident).any():     # not identifiable: the 95 % upper limit, as a downward triangle
                ax.plot(x[~ident], hi[~ident], "v", color=line[0].get_color(), alpha=0.6)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    ax = np.atleast_1d(axes)[-1]
    ax.set_xlabel("recording of the gyro (name order: 1 = first)")
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda x, _: f"{int(x) + 1}"))
    np.atleast_1d(axes)[0].legend(loc="best", fontsize=8, title="gyro")
    np.atleast_1d(axes)[0].set_title("whole-record IEEE-952 fit per recording (68.3 % intervals; "
                                      "\u25bd = not identifiable, 95 % upper limit)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _table(rows: list[dict], cols: list[tuple[str, str]]) -> str:
    head = "".join(f"<th>{html.escape(t)}</th>" for _, t in cols)
    body = []
    for r in rows:
        cells = []
        for k, _ in cols:
            v = r.get(k, "")
            cells.append(f"<td>{v:.4g}</td>" if isinstance(v, float) else f"<td>{html.escape(str(v))}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def report_files(path: str) -> list[str]:
    """The files the fleet report ``path`` (FLEET.html) is written as: itself,
    FLEET-trends.png and FLEET.csv beside it."""
    stem = os.path.splitext(path)[0]
    return [path, stem + "-trends.png", stem + ".csv"]


def write_report(path: str, recordings_parquet: str, windows_parquet: str,
                 flags: Mapping[str, str] | None = None) -> list[str]:
    """Write FLEET.html, FLEET-trends.png and FLEET.csv from the batch tables; returns
    the paths written. The page names parameters plainly, or as their flags in ``flags``
    (parameter name -> flag). Each file is complete or not written (fogmon.outputs.written;
    a disk error is a FogmonError naming it)."""
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    tbl = pq.read_table(recordings_parquet)
    rows = tbl.to_pylist()
    path, png, csv = report_files(path)
    with written(png, "`report`") as tmp:
        _trend_png(rows, tmp)
    with written(csv, "`report`") as tmp:
        pacsv.write_csv(tbl, tmp)
    ch = changes(rows)
    changed = [c for c in ch if c["changed"]]
    has_model = "explain_score_before" in tbl.column_names
    outside = [r for r in rows if has_model and not r["error"] and r["explain_score_before"] > SCORE_OUTSIDE]
    failed = [r for r in rows if r["error"]]
    n_win = pq.ParquetFile(windows_parquet).metadata.num_rows
    parts = [f"<h1>fogmon fleet report</h1><p>{html.escape(gyro_summary(rows))}, {n_win} windows; "
             f"{len(failed)} failed. "
             f"Tables: {html.escape(os.path.basename(csv))}, "
             f"{html.escape(os.path.basename(recordings_parquet))}, {html.escape(os.path.basename(windows_parquet))}."
             "</p>",
             f"<h2>Gyros whose N or B changed ({len(changed)})</h2><p>First vs latest recording of each gyro; "
             f"changed = |z| &gt; {Z_CHANGED:g} with z = difference / combined standard error (half the 68.3 % "
             "intervals), both estimates identifiable (chance: 0.27 % per coefficient and gyro).</p>",
             _table(changed, [("gyro", "gyro"), ("coefficient", "coefficient"), ("first_value", "first"),
                              ("latest_value", "latest"), ("z", "z"), ("latest", "latest recording")])
             if changed else "<p>None.</p>"]
    if has_model:
        parts += [f"<h2>Runs outside their model ({len(outside)})</h2><p>explain score before fitting effects "
                  f"&gt; {SCORE_OUTSIDE:g} (about 1 = within chance).</p>",
                  _table(outside, [("recording", "recording"), ("explain_score_before", "score"),
                                   ("explain_score_after", "score after effects"), ("explain_effects", "effects")])
                  if outside else "<p>None.</p>"]
    else:
        parts.append(render_names("<h2>Runs outside their model</h2><p>Not checked: run fogmon batch with `model` "
                                  "MODEL.toml.</p>", flags))
    parts += [f"<h2>Trends</h2><img src='{html.escape(os.path.basename(png))}' alt='N and B per recording'>",
              "<h2>All changes tested</h2>" + (_table(ch, [("gyro", "gyro"), ("coefficient", "coefficient"),
                                                            ("first_value", "first"), ("latest_value", "latest"),
                                                            ("z", "z"), ("changed", "changed"),
                                                            ("tested", "tested")]) if ch else
                                               "<p>No gyro has two analysed recordings.</p>")]
    if failed:
        parts += [f"<h2>Failed recordings ({len(failed)})</h2>", _table(failed, [("recording", "recording"),
                                                                                  ("error", "error")])]
    style = ("<style>body{font-family:sans-serif;max-width:1100px;margin:1em auto}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:2px 6px;font-size:90%}</style>")
    with written(path, "`report`") as tmp, open(tmp, "w", encoding="utf-8") as fh:
        fh.write(f"<!doctype html><html><head><meta charset='utf-8'><title>fogmon fleet report</title>{style}</head>"
                 f"<body>{''.join(parts)}</body></html>\n")
    return [path, png, csv]
