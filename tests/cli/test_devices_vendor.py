"""Issue 36, point 3: `benchlab devices` lists a device of the camera's vendor id with another
product id, with the exact bench-file and udev lines that make it the camera."""

from __future__ import annotations

from benchlab.cli.devices.camera import cameras_elsewhere
from benchlab.drivers.mightex.sim import SimCameraBackend, SimulatedCamera


def test_a_camera_of_another_product_id_is_listed_with_its_lines() -> None:
    backend = SimCameraBackend([SimulatedCamera(pid=0x0528), SimulatedCamera(serial="S2")])
    rows, notes = cameras_elsewhere(backend, None)
    assert [r["port"] for r in rows] == ["usb 1:2 04b4:0528"]  # the 0x0428 one is searched
    assert rows[0]["kind"] == "camera?" and rows[0]["model"] == "MCE-B013-U"
    [note] = notes
    assert "put `pid = 0x0528` under [camera]" in note
    assert note.endswith('ATTR{idVendor}=="04b4", ATTR{idProduct}=="0528", MODE="0660", '
                         'GROUP="plugdev", TAG+="uaccess"')
    assert cameras_elsewhere(backend, 0x0528)[0][0]["port"] == "usb 1:3 04b4:0428"
