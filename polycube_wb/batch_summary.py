# SPDX-License-Identifier: LGPL-2.1-or-later
"""The batch summaries: ``summary.csv`` (one row per mesh) and ``summary.html``.

The page is one self-contained file next to the per-mesh outputs: a table with each mesh's
thumbnail (a relative link to its PNG in the same folder), sortable by clicking a column
heading (inline script), failures first. Once loaded, the page replaces a thumbnail that
did not load by a note and records how many did in ``<body data-thumbnails>``. It fetches nothing from elsewhere.
"""
import csv
import html
import io

from core.output_files import write_text_atomic

COLUMNS = (("name", "mesh"), ("status", "status"), ("triangles", "triangles"),
           ("genus", "genus"), ("stage_reached", "stage reached"),
           ("failed_stage", "failed stage"), ("faces", "faces"),
           ("mean_deviation", "mean deviation (of diag.)"),
           ("max_deviation", "max deviation (of diag.)"),
           ("outside_volume", "volume outside (of vol.)"), ("seconds", "seconds"),
           ("peak_memory_mb", "peak memory (MiB)"), ("skipped", "skipped (up to date)"),
           ("message", "message"))
"""(MeshRow field, heading) of every column, in order (the CSV uses the field names)."""
NUMERIC = {"triangles", "genus", "faces", "mean_deviation", "max_deviation", "outside_volume",
           "seconds", "peak_memory_mb"}


def failures_first(rows):
    """Rows with status other than ``ok`` first, each group in the given order."""
    return sorted(rows, key=lambda row: row.status == "ok")


def write_summary_csv(path, rows, inputs=()):
    """Write ``summary.csv``: a header of MeshRow field names and one line per mesh."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([name for name, _ in COLUMNS] + ["source", "thumbnail"])
    for row in failures_first(rows):
        values = row.to_dict()
        writer.writerow([_csv_value(values[name]) for name, _ in COLUMNS]
                        + [row.source, row.thumbnail])
    return write_text_atomic(path, buffer.getvalue(), inputs, "summary CSV")


def _csv_value(value):
    return "" if value is None else value


def _cell(name, value):
    if value is None or value == "":
        return '<td data-v=""></td>'
    if name in NUMERIC:
        text = f"{value:.3g}" if isinstance(value, float) else str(value)
        return f'<td class="n" data-v="{value}">{text}</td>'
    if name == "skipped":
        return f'<td data-v="{int(value)}">{"yes" if value else ""}</td>'
    text = html.escape(str(value))
    return f'<td data-v="{text}">{text}</td>'


def write_summary_html(path, rows, inputs=(), title="Polycube batch"):
    """Write ``summary.html`` (see the module docstring); returns the absolute path."""
    ordered = failures_first(rows)
    head = "".join(f'<th data-k="{k + 1}" title="sort">{html.escape(heading)}</th>'
                   for k, (_, heading) in enumerate(COLUMNS))
    body = []
    for row in ordered:
        values = row.to_dict()
        picture = (f'<img src="{html.escape(row.thumbnail)}" alt="{html.escape(row.name)}" '
                   f'width="320">' if row.thumbnail else '<span class="none">no solid</span>')
        body.append(f'<tr class="{html.escape(row.status)}"><td>{picture}</td>'
                    + "".join(_cell(name, values[name]) for name, _ in COLUMNS) + "</tr>")
    failed = sum(row.status != "ok" for row in rows)
    page = _PAGE.format(title=html.escape(title), head=head, body="\n".join(body),
                        total=len(rows), solids=len(rows) - failed, failed=failed)
    return write_text_atomic(path, page, inputs, "summary page")


_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ font-family: sans-serif; margin: 1em; }}
table {{ border-collapse: collapse; }}
th, td {{ border: 1px solid #bbb; padding: 4px 6px; vertical-align: middle; font-size: 13px; }}
th {{ background: #eee; cursor: pointer; }}
td.n {{ text-align: right; font-variant-numeric: tabular-nums; }}
tr.failed td, tr.timeout td, tr.crashed td {{ background: #fdecea; }}
.none {{ color: #888; }}
</style></head><body>
<h1>{title}</h1>
<p id="counts">{total} meshes: {solids} solids, {failed} failed. Thumbnails: the solid
(coloured by its distance to the target, from white on it to red at the largest distance;
the scale in mm is on each image) over the target (translucent grey). Click a heading to sort.</p>
<table id="summary"><thead><tr><th>thumbnail</th>{head}</tr></thead>
<tbody>
{body}
</tbody></table>
<script>
document.querySelectorAll("#summary th[data-k]").forEach(function (th) {{
  th.addEventListener("click", function () {{
    var k = +th.dataset.k, body = document.querySelector("#summary tbody");
    var up = th.dataset.dir !== "up"; th.dataset.dir = up ? "up" : "down";
    var rows = Array.prototype.slice.call(body.rows);
    rows.sort(function (a, b) {{
      var x = a.cells[k].dataset.v, y = b.cells[k].dataset.v;
      var nx = parseFloat(x), ny = parseFloat(y);
      var c = (isNaN(nx) || isNaN(ny)) ? x.localeCompare(y) : nx - ny;
      return up ? c : -c;
    }});
    rows.forEach(function (r) {{ body.appendChild(r); }});
  }});
}});
window.addEventListener("load", function () {{
  var shown = 0;
  document.querySelectorAll("#summary img").forEach(function (img) {{
    if (img.complete && img.naturalWidth > 0) {{ shown++; return; }}
    var note = document.createElement("span");
    note.className = "none"; note.textContent = "thumbnail missing: " + img.getAttribute("src");
    img.replaceWith(note);
  }});
  document.body.dataset.thumbnails = shown;
}});
</script>
</body></html>
"""
