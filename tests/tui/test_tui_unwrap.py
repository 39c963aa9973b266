"""The live view's u key: the radial annulus shown unwrapped, and back."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_tui_helpers import make_app, open_live, wait_until


@pytest.mark.slow
@pytest.mark.asyncio
async def test_u_toggles_the_unwrapped_radial_view(tmp_path: Path) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        live = await open_live(pilot, 2)
        await pilot.press("t")  # the simulated bench mounts the radial sagittal pattern
        await wait_until(pilot, lambda: app.bench.mounted == ("radial", 2.0, "sagittal"),
                         what="radial target")
        await pilot.press("u")
        assert live.unwrapped

        def wide() -> bool:  # the full circle at 8 px/mm: ~1000 x 220, about 4.5 : 1
            r = live._latest
            return r is not None and r.preview.shape[1] > 4 * r.preview.shape[0]

        await wait_until(pilot, wide, what="unwrapped preview")
        reading = live._latest
        assert reading is not None and "unwrapped at 19.88 mm (centre" in reading.note
        assert reading.preview.max() > 0.5 * reading.max_code  # the lit annulus, unrolled
        assert "unwrapped" in str(live.query_one("#frame").border_title)
        await pilot.press("u")
        await wait_until(pilot, lambda: live._latest is not None
                         and live._latest.preview.shape[1] < 2 * live._latest.preview.shape[0],
                         what="raw preview again")
