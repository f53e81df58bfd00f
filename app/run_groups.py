"""The moves of one program run together (``meta.program``: ``control/program/runner.py``), as
the Runs tab lists them; ``servodesk runs list --program RUN_ID`` selects one the same way."""

from __future__ import annotations

import json

from control.recorder import RunInfo


def program_of(info: RunInfo) -> dict | None:
    """The run's ``meta.program`` (None: not a program's move, or unreadable)."""
    if info.damaged:
        return None
    try:
        program = json.loads(info.files.json.read_text(encoding="utf-8"))["meta"]["program"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return program if isinstance(program, dict) and program.get("run_id") else None


def grouped(infos: list[RunInfo], programs: dict[str, dict]) -> list[RunInfo]:
    """``infos`` (newest first) with each program run's moves together where its newest is,
    in the order the program made them."""
    members: dict[str, list[RunInfo]] = {}
    for info in infos:
        program = programs.get(info.files.stem)
        if program is not None:
            members.setdefault(str(program["run_id"]), []).append(info)
    out: list[RunInfo] = []
    for info in infos:
        program = programs.get(info.files.stem)
        if program is None:
            out.append(info)
        elif (group := members.pop(str(program["run_id"]), None)) is not None:
            out.extend(sorted(group, key=lambda i: programs[i.files.stem].get("visit", 0)))
    return out


def program_cell(program: object) -> str:
    """``pick and place #9e58 · step 4``: the program, the end of its run's id (the whole is
    in the run's details, for ``servodesk runs list --program``) and the step."""
    if not isinstance(program, dict):
        return ""
    run_id = str(program.get("run_id", ""))
    return f"{program.get('name', '')} #{run_id[-4:]} · step {program.get('step', '?')}"
