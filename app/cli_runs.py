"""``servodesk runs list|show|export``: the saved runs of the data directory, as the Runs tab
lists, describes and exports them; ``show --plot`` draws the response in the terminal
(``app.plotting.terminal``).

A run is named by its stem (as ``list`` prints it), the path of any of its files, or
``latest``. Exit 0 done, 2 bad input (no such run, a damaged run, one past its bounds or
not a regular file, an unknown view or format, an unwritable file), the message on stderr
in one line.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from app.cli_options import global_options
from app.run_text import local_time, run_lines, summary_table
from control.recorder import (
    RecorderError,
    Run,
    RunFiles,
    RunInfo,
    csv_text,
    default_data_dir,
    list_runs,
    load_run,
)
from hw.machine import Machine, MachineError, load_machine

FORMATS = ("svg", "txt", "csv", "mcap")


class BadRun(ValueError):
    """The run asked for cannot be read or exported; the message says why and what to do."""


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("runs", help="list, show or export the saved runs",
                       description="The runs saved in the data directory (--data-dir): list "
                                   "them, show one's summary and metrics, export one's plot.")
    actions = p.add_subparsers(title="actions", metavar="ACTION", required=True)
    common = argparse.ArgumentParser(add_help=False, parents=[global_options("data_dir")])
    common.add_argument("--json", action="store_true", help="machine-readable output")
    listing = actions.add_parser("list", parents=[common], help="one line per run, newest first")
    listing.add_argument("--program", metavar="RUN_ID|NAME",
                         help="only the runs of a program run (its id, as `servodesk run` "
                              "prints it) or of every run of a program (its name), in step order")
    listing.set_defaults(func=run, action=_list)
    show = actions.add_parser("show", parents=[common],
                              help="a run's fields, status and result metrics")
    show.add_argument("run", metavar="RUN", help="stem, a file of the run, or latest")
    show.add_argument("--machine", dest="run_machine",
                      help="the machine file, for a run of a machine that is not built in "
                           "(the metrics need its tolerances)")
    show.add_argument("--plot", action="store_true",
                      help="then draw desired, actual and duty of each joint that moved, "
                           "sized to the terminal (on stderr with --json)")
    show.set_defaults(func=run, action=_show)
    export = actions.add_parser(
        "export", parents=[common],
        help="a run's plot as the Runs tab exports it (svg, txt), or its CSV table")
    export.add_argument("run", metavar="RUN", help="stem, a file of the run, or latest")
    export.add_argument("--format", choices=FORMATS, default="svg",
                        help="svg (default) or txt: a plot; csv: the run's table; mcap: the "
                             "whole run for Foxglove or PlotJuggler (control/run_mcap.py)")
    export.add_argument("--view", help="the plot: plotsix-1-3, plotdata-<joint>, … (default "
                                       "the first the Runs tab shows)")
    export.add_argument("--out", metavar="FILE",
                        help="where to write (default: <data dir>/plots/<stem>-<view>.<format>)")
    export.set_defaults(func=run, action=_export)


def run(args: argparse.Namespace) -> int:
    data_dir = Path(args.data_dir).expanduser() if args.data_dir else default_data_dir()
    try:
        return args.action(args, data_dir)
    except BadRun as exc:
        print(f"servodesk: {exc}", file=sys.stderr)
        return 2


def _list(args: argparse.Namespace, data_dir: Path) -> int:
    infos = list_runs(data_dir)
    if args.program:
        infos = _of_program(infos, args.program)
    if args.json:
        print(json.dumps([{"stem": i.files.stem, "json": str(i.files.json),
                           "machine": i.machine or None, "kind": i.kind or None,
                           "status": i.status or None, "start_time": i.start_time or None,
                           "samples": i.samples, "problem": i.problem or None}
                          for i in infos], ensure_ascii=False))
        return 0
    if not infos:
        print(f"no runs in {data_dir}", file=sys.stderr)
    for i in infos:
        if i.damaged:
            print(f"{i.files.stem}  damaged: {i.problem}")
        else:
            print(f"{i.files.stem}  {local_time(i.start_time)}  {i.kind}  {i.status}  "
                  f"{i.samples} samples")
    return 0


def _of_program(infos: list[RunInfo], spec: str) -> list[RunInfo]:
    """The runs a program made (``meta.program``: control/program/runner.py) whose run id or
    name is ``spec``, oldest first: in the order the program made them."""
    found = []
    for info in infos:
        try:
            program = json.loads(info.files.json.read_text(encoding="utf-8"))["meta"]["program"]
        except (OSError, ValueError, KeyError, TypeError):
            continue  # not a program's run, or damaged (listed as such without --program)
        if isinstance(program, dict) and spec in (program.get("run_id"), program.get("name")):
            found.append(info)
    return found[::-1]


def _find(spec: str, data_dir: Path) -> RunFiles:
    """The run named by its stem, any of its files' paths, or ``latest``."""
    if spec == "latest":
        infos = list_runs(data_dir)
        if not infos:
            raise BadRun(f"RUN latest: no runs in {data_dir}")
        return infos[0].files
    path = Path(spec).expanduser()
    files = RunFiles.from_json(path if path.parent != Path() else data_dir / spec)
    if not files.json.exists():  # anything else there is refused by the loader, saying what
        raise BadRun(f"RUN {spec}: no run {files.json} (`servodesk runs list` names them)")
    return files


def _load(spec: str, data_dir: Path) -> tuple[RunFiles, Run]:
    files = _find(spec, data_dir)
    try:
        return files, load_run(files.json)
    except RecorderError as exc:
        raise BadRun(f"RUN {spec}: {exc}") from None


def _machine(run: Run, spec: str | None) -> tuple[Machine | None, str]:
    """The run's machine (``spec`` if given), or None and why."""
    try:
        return load_machine(spec or run.machine), ""
    except MachineError as exc:
        return None, f"no metrics: {exc}; pass --machine FILE"


def _show(args: argparse.Namespace, data_dir: Path) -> int:
    from control.motion.plan import result_records, run_summaries

    files, run = _load(args.run, data_dir)
    machine, problem = _machine(run, args.run_machine)
    summaries = run_summaries(run, machine) if machine is not None else []
    if args.json:
        print(json.dumps({
            "stem": files.stem, "json": str(files.json), "machine": run.machine,
            "kind": run.kind, "status": run.status, "start_time": run.start_time,
            "samples": run.samples, "sample_time_s": run.sample_time_s,
            "meta": run.meta, "metrics": result_records(summaries),
            "problem": problem or None}, ensure_ascii=False, default=str))
    else:
        print("\n".join(run_lines(run, files.stem)))
        print(problem or "\n".join(summary_table(summaries)))
    if args.plot:
        from app.plotting.terminal import print_response

        sys.stdout.flush()
        print_response(run, sys.stderr if args.json else sys.stdout)
    return 0


def _export(args: argparse.Namespace, data_dir: Path) -> int:
    from app.plotting.run_plot import export, view_figure, view_slug, views
    from control.run_mcap import write_mcap

    files, run = _load(args.run, data_dir)
    shown = views(run)
    slugs = [view_slug(v).lower() for v in shown]
    if args.format in ("csv", "mcap"):
        if args.view:
            raise BadRun(f"--view: a {args.format.upper()} export is the whole run; leave "
                         "--view out")
        view = ""
    elif args.view is None:
        view = shown[0]
    elif view_slug(args.view).lower() in slugs:
        view = shown[slugs.index(view_slug(args.view).lower())]
    else:
        raise BadRun(f"--view {args.view}: this run's plots are "
                     f"{', '.join(view_slug(v) for v in shown)}")
    name = f"{files.stem}-{view_slug(view)}" if view else files.stem
    out = (Path(args.out).expanduser() if args.out
           else data_dir / "plots" / f"{name}.{args.format}")
    try:
        if args.format == "csv":
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(csv_text(run), encoding="utf-8")  # the saved CSV, unpacked
            written = [out]
        elif args.format == "mcap":
            out.parent.mkdir(parents=True, exist_ok=True)
            written = [write_mcap(run, out)]
        else:
            written = export(out, view_figure(run, view, f"{files.stem} · {run.status}"),
                             formats=(args.format,))
    except OSError as exc:
        raise BadRun(f"--out: cannot write {out}: {exc.strerror or exc}") from None
    for path in written:
        print(path)
    return 0
