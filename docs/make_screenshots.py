"""Regenerate the screenshots of every tab in ``docs/screenshots/`` (SVG, from Textual).

Run: ``python docs/make_screenshots.py`` (about two minutes). The app runs
headless at 160 × 48 against the real-time simulated Unimate 2000B: it jogs a joint,
runs an Up/Down step from the Moves tab (and watches it on the Scope), identifies Bend,
then saves each tab as the operator would see it. Then every tab again at 80 × 24, the
smallest terminal servodesk is laid out for, in ``docs/screenshots/80x24/``. Runs go to
a temporary directory; ``--rig`` adds the rig's Jog and Moves tabs; ``--small`` makes
only the 80 × 24 ones; ``--arm`` only the arm's view (``arm*.svg``, both sizes, and the
rig's). Every SVG is written to load nothing from the network (``offline``: Textual's names
its font on a CDN); ``--offline`` makes the SVGs already there so, without running the app.
"""

from __future__ import annotations

import argparse
import asyncio
import re
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from textual.pilot import Pilot
from textual.widgets import Input, OptionList, TextArea

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.tabs.identify import IdentifyTab
from app.tabs.moves import MovesTab
from app.tabs.runs import RunsTab
from app.tui import ServodeskApp
from app.widgets.fields import NumberField
from control.rt.layout import Flag

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "screenshots"
SIZE = (160, 48)
SMALL = (80, 24)
# A headless app on a loaded two-core machine can pause its client's heartbeat thread past
# 250 ms (the tests allow it 2 s too): the screenshots would all show that fault's banner.
CLIENT = {"heartbeat_timeout_s": 2.0}


async def wait_for(condition: Callable[[], object], timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError("the app did not get there in time")
        await asyncio.sleep(0.05)


# a font Textual's SVG loads from a CDN after the local one: `, url("https://…") format("woff2")`
REMOTE_FONT = re.compile(r',\s*url\("https?://[^"]*"\)\s*format\("[^"]*"\)')


def offline(svg: str) -> str:
    """``svg`` loading nothing from the network: its fonts only by their local names (a
    viewer without Fira Code draws the text in its monospace, as the SVG's font-family
    says), so the README shows the same offline and sends no reader to a CDN."""
    return REMOTE_FONT.sub("", svg)


def save(app: ServodeskApp, name: str, folder: Path = OUT) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    path = Path(app.save_screenshot(filename=f"{name}.svg", path=str(folder)))
    path.write_text(offline(path.read_text(encoding="utf-8")), encoding="utf-8")
    print(f"wrote {path.relative_to(ROOT)}")


def make_offline() -> None:
    """Every SVG already in ``docs/screenshots/`` rewritten by ``offline``."""
    for path in sorted(OUT.rglob("*.svg")):
        text = path.read_text(encoding="utf-8")
        if (kept := offline(text)) != text:
            path.write_text(kept, encoding="utf-8")
            print(f"wrote {path.relative_to(ROOT)}")


async def latest_run(app: ServodeskApp, pilot: Pilot) -> None:
    """The Runs tab with the newest run open on its Up/Down plot."""
    await pilot.press("f6")
    runs = app.query_one(RunsTab)
    await wait_for(lambda: bool(runs.infos))
    runs.open_latest()
    await wait_for(lambda: runs.run is not None)
    runs.view = runs.views().index("plotdata Up/Down")
    runs.draw()
    await pilot.pause(0.8)


async def unimate(data_dir: str) -> None:
    app = ServodeskApp("unimate2000b", data_dir=data_dir, client_options=CLIENT)
    async with app.run_test(size=SIZE) as pilot:
        await wait_for(lambda: app.sampler is not None and app.sampler.latest is not None)
        await pilot.pause(1.0)
        await pilot.press("3", "s", "s", "s", "s", "s", "s", "s", "s")  # Rotate at 24 %
        await pilot.pause(1.5)
        save(app, "jog")
        await pilot.press("space", "enter")

        await pilot.press("f2")
        await pilot.pause(0.3)
        app.query_one("#move-kinds", OptionList).highlighted = 0
        await pilot.pause(0.3)
        app.query_one("#form-step JointField Select").value = 2
        position = app.client.status().position[2]
        app.query_one("#form-step #target", NumberField).text = f"{position + 8:.1f}"
        await pilot.pause(0.8)
        moves = app.query_one(MovesTab)
        await pilot.press("ctrl+s")
        await wait_for(lambda: moves.handle is not None)
        await pilot.pause(0.6)
        save(app, "moves-running")
        await pilot.press("f3")  # the step as it happens
        await pilot.pause(1.5)
        save(app, "scope")
        await pilot.press("f2")
        await wait_for(lambda: moves.handle is None)
        await pilot.pause(0.5)
        save(app, "moves")

        await pilot.press("f4")
        await pilot.pause(0.8)
        save(app, "status")
        await pilot.press("f5")
        await pilot.pause(0.8)
        save(app, "tuning")
        await latest_run(app, pilot)
        save(app, "runs")
        await pilot.press("f7")
        await pilot.pause(1.0)
        save(app, "latency")
        await pilot.press("f8")
        identify = app.query_one(IdentifyTab)
        await pilot.pause(0.3)
        app.query_one("#identify-joint Select").value = 3  # Bend
        app.query_one("#identify-duration", NumberField).text = "3"
        await pilot.pause(0.3)
        await pilot.click("#identify-run")
        await wait_for(lambda: 3 in identify.held_out, timeout=120)
        app.query_one("#identify-ff").value = True
        await pilot.pause(0.8)
        save(app, "identify")
        await pilot.press("f9")
        await pilot.pause(0.5)
        await pilot.press("t")  # teach where the joints are
        app.screen.query_one(Input).value = "over the fixture"
        await pilot.press("enter")
        await pilot.pause(0.8)
        save(app, "positions")
        await pilot.press("escape")
        await pilot.pause(0.5)
        save(app, "estop")


async def rig(data_dir: str) -> None:
    app = ServodeskApp("rig", data_dir=data_dir, client_options=CLIENT)
    async with app.run_test(size=SIZE) as pilot:
        await wait_for(lambda: app.sampler is not None and app.sampler.latest is not None)
        await pilot.press("up", "up")
        await pilot.pause(1.0)
        save(app, "rig-jog")
        await pilot.press("space", "f2")
        await pilot.pause(0.3)
        app.query_one("#move-kinds", OptionList).highlighted = 1  # the sequence
        await pilot.pause(0.3)
        for i, (position, dwell) in enumerate(((300, 2), (600, 2), (200, 3))):
            app.query_one(f"#form-multi_step #pos{i}", NumberField).text = str(position)
            app.query_one(f"#form-multi_step #dwell{i}", NumberField).text = str(dwell)
        await pilot.pause(0.8)
        save(app, "rig-moves")


async def arm_view(data_dir: str, size: tuple[int, int], folder: Path) -> None:
    """The arm's view: on the Jog tab (p), and on its own screen (^A) while a via-points move
    runs towards Up/Down's limit (amber), its path and the desired pose ahead of the arm."""
    app = ServodeskApp("unimate2000b", data_dir=data_dir, client_options=CLIENT)
    async with app.run_test(size=size) as pilot:
        await wait_for(lambda: app.sampler is not None and app.sampler.latest is not None)
        await wait_for(lambda: all(tab.is_mounted for tab in app.tabs.values()))
        await pilot.pause(1.0)
        await pilot.press("p")
        await pilot.pause(1.0)
        save(app, "arm-jog", folder)
        await pilot.press("p", "f2")
        await pilot.pause(0.3)
        kinds = app.query_one("#move-kinds", OptionList)
        kinds.highlighted = next(i for i in range(kinds.option_count)
                                 if str(kinds.get_option_at_index(i).prompt) == "Via points")
        await pilot.pause(0.3)
        q = list(app.client.status().position)
        via = [q[0] + 250, q[1] + 40, 10.0, q[3] + 20, 35.0, q[5]]
        end = [q[0] + 450, q[1] + 75, 27.0, q[3] + 30, 60.0, q[5] + 45]
        app.query_one("#via-points", TextArea).text = "\n".join(
            " ".join(f"{v:.2f}" for v in row) for row in (via, end))
        moves = app.query_one(MovesTab)
        await wait_for(lambda: moves.previewed is not None)
        await pilot.pause(0.5)
        await pilot.press("ctrl+s")
        await wait_for(lambda: moves.handle is not None)
        await pilot.press("ctrl+a", "plus")
        await pilot.pause(5.0)
        save(app, "arm", folder)
        await pilot.press("ctrl+g")


async def rig_arm(data_dir: str) -> None:
    """The rig's ram on its own screen (^A) on its way to a target."""
    app = ServodeskApp("rig", data_dir=data_dir, client_options=CLIENT)
    async with app.run_test(size=SIZE) as pilot:
        await wait_for(lambda: app.sampler is not None and app.sampler.latest is not None)
        await pilot.pause(1.0)
        app.client.initialise()  # the encoder zeroed at the bottom stop: then it moves
        await wait_for(lambda: app.client.status().flags & Flag.HOMED, timeout=60)
        app.client.go_to([800.0], speed=0.3)
        await pilot.press("ctrl+a")
        await pilot.pause(2.0)
        save(app, "rig-arm")


async def small(data_dir: str) -> None:
    """Every tab at 80 × 24: a jog, an Up/Down step previewed with its approach, then run
    (its result table), the run's plot, and the others as they open."""
    folder = OUT / f"{SMALL[0]}x{SMALL[1]}"
    app = ServodeskApp("unimate2000b", data_dir=data_dir, client_options=CLIENT)
    async with app.run_test(size=SMALL) as pilot:
        await wait_for(lambda: app.sampler is not None and app.sampler.latest is not None)
        await pilot.pause(1.0)
        await pilot.press("3", "s", "s", "s", "s", "s", "s", "s", "s")  # Rotate at 24 %
        await pilot.pause(1.5)
        save(app, "jog", folder)
        await pilot.press("space", "enter")
        await pilot.press("f2")
        await pilot.pause(0.3)
        app.query_one("#move-kinds", OptionList).highlighted = 0
        await pilot.pause(0.3)
        app.query_one("#form-step JointField Select").value = 2
        await pilot.pause(0.3)
        position = app.client.status().position[2]
        app.query_one("#form-step #start", NumberField).text = f"{position - 2:.1f}"
        app.query_one("#form-step #target", NumberField).text = f"{position + 6:.1f}"
        await pilot.pause(0.8)
        save(app, "moves-preview", folder)
        moves = app.query_one(MovesTab)
        await pilot.press("ctrl+s")
        await wait_for(lambda: moves.handle is not None)
        await wait_for(lambda: moves.handle is None)
        await pilot.pause(0.5)
        save(app, "moves", folder)
        for key, name in (("f3", "scope"), ("f4", "status"), ("f5", "tuning")):
            await pilot.press(key)
            await pilot.pause(1.0)
            save(app, name, folder)
        await latest_run(app, pilot)
        save(app, "runs", folder)
        for key, name in (("f7", "latency"), ("f8", "identify"), ("f9", "positions")):
            await pilot.press(key)
            await pilot.pause(1.0)
            save(app, name, folder)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rig", action="store_true", help="also the rig's Jog and Moves tabs")
    parser.add_argument("--small", action="store_true", help="only the 80 × 24 screenshots")
    parser.add_argument("--arm", action="store_true", help="only the arm's view, both sizes")
    parser.add_argument("--offline", action="store_true",
                        help="only rewrite the SVGs there to load nothing from the network")
    args = parser.parse_args()
    if args.offline:
        make_offline()
        return
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as data_dir:
        if args.arm or not args.small:
            asyncio.run(arm_view(data_dir, SIZE, OUT))
            asyncio.run(arm_view(data_dir, SMALL, OUT / f"{SMALL[0]}x{SMALL[1]}"))
            asyncio.run(rig_arm(data_dir))
        if args.arm:
            return
        if not args.small:
            asyncio.run(unimate(data_dir))
            if args.rig:
                asyncio.run(rig(data_dir))
        asyncio.run(small(data_dir))


if __name__ == "__main__":
    main()
