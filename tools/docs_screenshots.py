"""Regenerate the screenshots the docs show, from runs on the simulated bench.

- ``docs/img/tui-depth-80x24.svg``: the TUI's Run screen after a depth-of-field run in an 80x24
  terminal (Textual's own SVG screenshot: text, not pixels);
- ``docs/img/report-bar-contrast.png``: the MTF report's "Measured vs simulated bar contrast"
  section in headless Chromium (Debian's ``chromium``).

Run from the repository root: ``python tools/docs_screenshots.py``. Each file is checked to
stay under :data:`MAX_BYTES` (the repository keeps small files only).
"""

from __future__ import annotations

import asyncio
import io
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "img"
FIXTURES = ROOT / "fixtures" / "params"
MAX_BYTES = 300_000


async def tui_depth(tmp: Path) -> str:
    """The SVG of the Run screen at 80x24 after the small depth run."""
    from benchlab.tui.app import BenchlabApp
    from benchlab.tui.dialogs import PromptDialog
    from benchlab.tui.runner import RunScreen

    params = tmp / "depth.toml"
    params.write_text((FIXTURES / "depth-small.toml").read_text(encoding="utf-8"))
    app = BenchlabApp(simulate=True, sessions_dir=tmp / "sessions",
                      params_files={"depth": params})
    async with app.run_test(size=(80, 24)) as pilot:
        deadline = time.monotonic() + 120.0
        while app.bench is None:  # type: ignore[attr-defined]
            assert time.monotonic() < deadline, "the simulated bench did not connect"
            await pilot.pause(0.05)
        await pilot.press("3", "p", "p", "p")
        screen = app.screen
        assert isinstance(screen, RunScreen) and screen.procedure == "depth"
        await pilot.pause(0.5)
        await pilot.press("s")
        answered = None
        while screen.state in ("idle", "running") or isinstance(app.screen, PromptDialog):
            assert time.monotonic() < deadline + 120.0, "the depth run did not end"
            if isinstance(app.screen, PromptDialog) and app.screen is not answered:
                answered = app.screen
                await pilot.press("y")
            await pilot.pause(0.05)
        assert screen.state == "done", screen.message
        await pilot.pause(0.3)
        return app.export_screenshot(title="benchlab: depth of field at 80x24")


def report_section(tmp: Path) -> bytes:
    """A PNG of the MTF report's bar-contrast section (the small simulated run)."""
    from PIL import Image, ImageOps

    from benchlab.bench import Bench, BenchConfig
    from benchlab.protocols import start_run
    from benchlab.report.render import write_report

    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        raise SystemExit("docs_screenshots: error: needs chromium for the report screenshot")
    params = tmp / "mtf.toml"
    params.write_text((FIXTURES / "mtf-small.toml").read_text(encoding="utf-8")
                      .replace('estimator = "histogram"', 'estimator = "auto"'))
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True) as bench:
        outcome = start_run("mtf", bench=bench, params=params, root=tmp / "sessions",
                            operator="docs", prompt=lambda step, message: True).run()
    text = write_report(outcome.session_path).read_text(encoding="utf-8")
    # The section alone, with the report's own style: a headless screenshot shows a page's top.
    head = text[:text.index("<body")]
    start = text.index("<section id='ctf'>")
    section = text[start:text.index("</section>", start) + len("</section>")]
    page = tmp / "section.html"
    page.write_text(f"{head}<body>{section}</body></html>", encoding="utf-8")
    shot = tmp / "report.png"
    subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    f"--user-data-dir={tmp / 'profile'}", "--window-size=1100,1450",
                    f"--screenshot={shot}", page.as_uri()],
                   check=True, capture_output=True, timeout=120)
    image = Image.open(shot).convert("RGB")
    box = ImageOps.invert(image).getbbox()  # the page without its blank margin
    if box is not None:
        image = image.crop((0, 0, image.width, min(image.height, box[3] + 20)))
    image = image.resize((image.width * 3 // 4, image.height * 3 // 4), Image.LANCZOS)
    buf = io.BytesIO()
    image.quantize(colors=256, method=Image.Quantize.FASTOCTREE).save(buf, format="PNG",
                                                                     optimize=True)
    return buf.getvalue()


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        svg = asyncio.run(tui_depth(Path(tmp))).encode("utf-8")
        (OUT / "tui-depth-80x24.svg").write_bytes(svg)
        png = report_section(Path(tmp))
        (OUT / "report-bar-contrast.png").write_bytes(png)
    for name, data in (("tui-depth-80x24.svg", svg), ("report-bar-contrast.png", png)):
        print(f"docs/img/{name}: {len(data) / 1000:.0f} kB")
        if len(data) > MAX_BYTES:
            print(f"docs_screenshots: error: {name} is over {MAX_BYTES} bytes", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
