"""A run as MCAP, the container Foxglove and PlotJuggler open: JSON messages on JSON-schema
channels, one message per sample per channel, stamped with the run's wall-clock time.

Channels (topic: one message holds):

- ``/joints/desired``, ``/joints/actual``: each joint's position by name (mm, deg);
- ``/joints/duty``: each joint's valve duty by name (%), what the valves were sent
  after the guards (a run records no other valve signal);

  every number at the precision the run's own tables have (``control/recorder.py``:
  desired to its max_accel's decimals, actual to a tenth of an encoder count, duty to
  0.01 %), written by the same writer; NaN (no desired position, open loop) is null;
- ``/events``: the run's status at its end, and its stalls, feed changes and feed holds
  (``gaps``, ``feed``, ``pauses`` of its metadata), each at its time;
- ``/gains``: the coefficient sets in use, once at the start.

The run's metadata (machine, kind, start, sample time, joints and units, everything in
``Run.meta``) is an MCAP metadata record named ``servodesk.run``. CSV/TSV/JSON stay the
run's own files; this is an export (``servodesk runs export --format mcap``, the Runs tab).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader
from mcap.writer import Writer

from control import decimal_text
from control.decimal_text import Block, Cells, slots
from control.recorder import ROWS_AT_ONCE, Run, joint_cells, json_numbers

JOINT_TOPICS = {"/joints/desired": "desired", "/joints/actual": "actual",
                "/joints/duty": "duty"}
METADATA = "servodesk.run"
NOT_FINITE = {"nan": "null", "inf": "null", "-inf": "null"}  # as the tables spell them
EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


def write_mcap(run: Run, path: Path) -> Path:
    """Write ``run`` to ``path`` (``.mcap``), complete or not at all: a temporary file in the
    same directory renamed into place."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with tmp.open("wb") as stream:
            _write(run, stream)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _write(run: Run, stream: Any) -> None:
    writer = Writer(stream)
    writer.start(profile="", library="servodesk")
    start_ns = _epoch_ns(run.start_time)
    stamps = start_ns + np.round(run.t * 1e9).astype(np.int64)
    names = run.joint_names
    for (topic, field_name), cells in zip(JOINT_TOPICS.items(), joint_cells(run), strict=True):
        unit = "%" if field_name == "duty" else None
        schema = writer.register_schema(
            f"servodesk.joints.{field_name}", "jsonschema", _joint_schema(names, run, unit))
        channel = writer.register_channel(topic, "json", schema)
        for i, (stamp, row) in enumerate(zip(stamps.tolist(), _json_rows(names, cells,
                                                                         run.samples),
                                             strict=True)):
            writer.add_message(channel, stamp, row, stamp, i)
    _write_events(writer, run, start_ns, int(stamps[-1]) if len(stamps) else start_ns)
    schema = writer.register_schema("servodesk.gains", "jsonschema", json.dumps(
        {"type": "object", "description": "the coefficient sets of eq. 5.1 in use"}).encode())
    channel = writer.register_channel("/gains", "json", schema)
    gains = json.dumps(json_numbers(run.coefficients), default=str).encode()
    writer.add_message(channel, start_ns, gains, start_ns, 0)
    writer.add_metadata(METADATA, {key: json.dumps(value, default=str)
                                   for key, value in _run_record(run).items()})
    writer.finish()


def _write_events(writer: Writer, run: Run, start_ns: int, end_ns: int) -> None:
    schema = writer.register_schema("servodesk.event", "jsonschema", json.dumps({
        "type": "object",
        "properties": {"kind": {"type": "string"}, "text": {"type": "string"},
                       "t_s": {"type": "number"}, "value": {"type": "number"}},
    }).encode())
    channel = writer.register_channel("/events", "json", schema)
    for sequence, (stamp, event) in enumerate(sorted(_events(run, start_ns, end_ns),
                                                     key=lambda e: e[0])):
        writer.add_message(channel, stamp, json.dumps(event).encode(), stamp, sequence)


def _events(run: Run, start_ns: int, end_ns: int) -> Iterator[tuple[int, dict[str, Any]]]:
    def at(t: float) -> int:
        return start_ns + round(t * 1e9)

    for t, length in run.meta.get("gaps", []):
        yield at(t), {"kind": "stall", "t_s": t, "value": length,
                      "text": f"controller stalled {length:.3f} s"}
    for t, override in run.meta.get("feed", []):
        yield at(t), {"kind": "feed", "t_s": t, "value": override,
                      "text": f"feed override {override:.0%}"}
    for t, length in run.meta.get("pauses", []):
        yield at(t), {"kind": "feed hold", "t_s": t, "value": length,
                      "text": f"feed hold {length:.3f} s"}
    yield end_ns, {"kind": "end", "t_s": (end_ns - start_ns) / 1e9, "text": run.status}


def _joint_schema(names: tuple[str, ...], run: Run, unit: str | None) -> bytes:
    units = [unit or u for u in run.joint_units]
    return json.dumps({
        "type": "object",
        "properties": {name: {"type": ["number", "null"], "description": u}
                       for name, u in zip(names, units, strict=True)},
    }).encode()


def _json_rows(names: tuple[str, ...], cells: Callable[[slice], Cells], samples: int
               ) -> Iterator[bytes]:
    """Each row as a JSON object by joint name, its numbers as the run's tables write them
    (``cells``, a block of rows at a time); NaN (no desired position in an open-loop move)
    and ±inf are null."""
    template = "{" + ", ".join(f"{json.dumps(name)}: %s" for name in names) + "}"
    for a in range(0, samples, ROWS_AT_ONCE):
        text = decimal_text.lines([Block.of(slots(cells(slice(a, a + ROWS_AT_ONCE))))], b",")
        for line in text.tobytes().decode().splitlines():
            yield (template % tuple(NOT_FINITE.get(v, v) for v in line.split(","))).encode()


def _run_record(run: Run) -> dict[str, Any]:
    return {"machine": run.machine, "kind": run.kind, "status": run.status,
            "start_time": run.start_time, "sample_time_s": run.sample_time_s,
            "joints": [list(j) for j in zip(run.joint_names, run.joint_units, strict=True)],
            "meta": json_numbers(dict(run.meta))}


def _epoch_ns(stamp: str) -> int:
    """Nanoseconds since the Unix epoch of an ISO 8601 time, exactly (no float seconds)."""
    since = datetime.fromisoformat(stamp.replace("Z", "+00:00")) - EPOCH
    return since // timedelta(microseconds=1) * 1000


def read_mcap(path: Path) -> tuple[dict[str, Any], dict[str, list[tuple[int, Any]]]]:
    """What an MCAP file of a run holds: its ``servodesk.run`` metadata, and each topic's
    messages as (log time ns, decoded JSON) in order."""
    with Path(path).open("rb") as stream:
        reader = make_reader(stream)
        record = {}
        for metadata in reader.iter_metadata():
            if metadata.name == METADATA:
                record = {k: json.loads(v) for k, v in metadata.metadata.items()}
        topics: dict[str, list[tuple[int, Any]]] = {}
        for _, channel, message in reader.iter_messages(log_time_order=True):
            topics.setdefault(channel.topic, []).append((message.log_time,
                                                         json.loads(message.data)))
    return record, topics
