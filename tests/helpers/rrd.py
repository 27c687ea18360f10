"""An .rrd file read back (rerun.chunk.RrdReader): the scalars, one component column,
the text log and the blueprint's views of an entity, as the Rerun sink wrote them."""
from __future__ import annotations

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader


def read_scalars(path, entity):
    """(times in s, values rows) of a Scalars entity in an .rrd."""
    ts, vals = [], []
    for ch in RrdReader(path).stream().filter(content=entity, is_static=False):
        rb = ch.to_record_batch()
        if "Scalars:scalars" not in rb.schema.names:
            continue
        ts += list(rb.column("time").cast(pa.int64()).to_numpy() / 1e9)
        vals += rb.column("Scalars:scalars").to_pylist()
    order = np.argsort(ts, kind="stable")
    return np.array(ts)[order], np.array(vals, dtype=np.float64)[order]


def read_column(path, entity, column):
    """(times in s, or None for static rows; values) of one component column of an entity."""
    out = []
    for ch in RrdReader(path).stream().filter(content=entity):
        rb = ch.to_record_batch()
        if column not in rb.schema.names:
            continue
        ts = rb.column("time").cast(pa.int64()).to_numpy() / 1e9 if "time" in rb.schema.names else [None] * rb.num_rows
        out += list(zip(ts, rb.column(column).to_pylist(), strict=True))
    return out


def read_texts(path, entity):
    """The text log messages of an entity, in file order."""
    out = []
    for ch in RrdReader(path).stream().filter(content=entity, is_static=False):
        rb = ch.to_record_batch()
        if "TextLog:text" in rb.schema.names:
            out += [x[0] for x in rb.column("TextLog:text").to_pylist()]
    return out


def read_event_messages(path, entity):
    """The events' messages in an .rrd without the recording time that leads each
    (``sink.event_text``: "12.50 s  crc_error: ...")."""
    return [x.split(" s  ", 1)[1] for x in read_texts(path, entity)]


def read_views(path):
    """The views of an .rrd's blueprint: display name -> {class, origin, contents, and
    ``props``: its properties (``/view/<id>/<property>`` -> {component: value})}."""
    reader = RrdReader(path)
    (store,) = reader.blueprints()
    parts: dict[str, dict] = {}
    for ch in reader.stream(store=store):
        ent = str(ch.entity_path)
        if not ent.startswith("/view/"):
            continue
        view = parts.setdefault(ent.split("/")[2], {"props": {}})
        for row in ch.to_record_batch().to_pylist():
            if ent.count("/") > 2 and row.get("ViewContents:query") is None:   # PlotLegend, TextLogColumns, ...
                view["props"].setdefault(ent.split("/", 3)[3], {}).update(
                    {k: v for k, v in row.items() if ":" in k and v is not None})
                continue
            for k, col in (("class", "ViewBlueprint:class_identifier"), ("name", "ViewBlueprint:display_name"),
                           ("origin", "ViewBlueprint:space_origin"), ("contents", "ViewContents:query")):
                if row.get(col) is not None:
                    view[k] = row[col] if k == "contents" else row[col][0]
    return {v["name"]: v for v in parts.values()}


def rgb(packed):
    """(r, g, b) of a Rerun colour (0xRRGGBBAA)."""
    return (packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255
