"""Which frames the live view and the measurements take, counted at the simulated camera.

The live view shows the camera's newest frame without waiting for a new exposure (one frame
read per refresh); a measurement frame (a procedure's step, the back-focus sharpness) is
exposed wholly after the request: the buffer is cleared and the exposure under way dropped,
so two frames are read per frame used.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from sim_runs import RAD_SMALL
from test_tui_helpers import make_app, open_live, wait_until

from benchlab.bench import Bench, BenchConfig
from benchlab.protocols import start_run
from benchlab.tui import services


@pytest.mark.slow
@pytest.mark.asyncio
async def test_live_view_reads_one_camera_frame_per_refresh(tmp_path: Path) -> None:
    app = make_app(tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        live = await open_live(pilot, 2)
        camera = app.bench.sim_camera

        def sample() -> tuple[int, int]:
            with app.device_lock:  # no grab under way: a published reading is complete
                reading = live._latest
                assert reading is not None
                return reading.index, camera.frames_sent

        index0, sent0 = sample()
        await wait_until(pilot, lambda: sample()[0] >= index0 + 12, what="12 live frames")
        index1, sent1 = sample()
        grabs = index1 - index0
        # Waiting for a fresh exposure reads two frames per grab (22+ here); the newest
        # frame, one (+-1: a grab done, its reading not yet published, at either sample).
        assert grabs - 1 <= sent1 - sent0 <= grabs + 1
        assert camera.frames_sent > 0 and app.bench.camera.discarded_frames == 0


@pytest.mark.slow
def test_measurement_frames_are_still_exposed_after_the_request(tmp_path: Path) -> None:
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True,
                    time_scale=20.0) as bench:
        camera = bench.sim_camera
        assert camera is not None
        sent = camera.frames_sent
        outcome = start_run("radiometry", bench=bench, params=RAD_SMALL, root=tmp_path,
                            prompt=lambda step, message: True).run()
        saved = len(list(Path(outcome.session_path).rglob("*.tif*")))
        assert saved == 6
        assert camera.frames_sent - sent >= 2 * saved  # each: the stale one, then its own

        sent = camera.frames_sent
        services.focus_sharpness(bench, runner=object())  # back-focus reading: fresh too
        assert camera.frames_sent - sent == 2
        sent = camera.frames_sent
        services.grab(bench, 300.0, 1.0, fresh=False)  # the live view's grab, for contrast
        assert camera.frames_sent - sent == 1
