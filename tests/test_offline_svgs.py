"""The README's screenshots and the docs' figures load nothing from the network (issue 26
item 6): no font, stylesheet or image by an http(s) URL, so they look the same offline and
send no reader to a CDN; and the screenshot maker writes them so (``docs/make_screenshots``)."""

from __future__ import annotations

import importlib.util
import io
import re
from pathlib import Path

import pytest
from rich.console import Console

ROOT = Path(__file__).resolve().parents[1]
# what a browser fetches: a CSS url() or @import, an href or src attribute (an XML namespace
# or a DOCTYPE names a URL but loads nothing)
LOADS = re.compile(r"""url\(\s*["']?\s*https?:|@import|(?:href|src)\s*=\s*["']\s*https?:""",
                   re.IGNORECASE)
SVGS = sorted((ROOT / "docs").rglob("*.svg"))


def test_the_docs_have_svgs_to_check() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    shown = {ROOT / name for name in re.findall(r"\]\((docs/[^)]+\.svg)\)", readme)}
    assert shown and shown <= set(SVGS)


@pytest.mark.parametrize("svg", SVGS, ids=[str(p.relative_to(ROOT)) for p in SVGS])
def test_an_svg_loads_nothing_from_the_network(svg: Path) -> None:
    text = svg.read_text(encoding="utf-8")
    assert not [m.group(0) for m in LOADS.finditer(text)], svg


def test_the_screenshot_maker_keeps_only_the_local_font() -> None:
    spec = importlib.util.spec_from_file_location("make_screenshots",
                                                  ROOT / "docs" / "make_screenshots.py")
    assert spec is not None and spec.loader is not None
    maker = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(maker)
    console = Console(record=True, width=40, file=io.StringIO())
    console.print("[bold]E-STOP[/] latched")
    svg = console.export_svg(title="servodesk")  # as Textual's save_screenshot writes it
    assert LOADS.search(svg)  # Rich's own: Fira Code from a CDN
    kept = maker.offline(svg)
    assert not LOADS.search(kept)
    assert 'local("FiraCode-Regular")' in kept and "E-STOP" in kept
