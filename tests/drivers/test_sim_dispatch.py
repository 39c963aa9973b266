"""The three simulators route commands the same way: one CommandTable per simulator class."""

from __future__ import annotations

import pytest

from benchlab.drivers.apt.protocol import Msg
from benchlab.drivers.apt.sim import SimulatedAptStage
from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.mightex.sim import SimulatedCamera
from benchlab.drivers.simulation.dispatch import CommandTable
from benchlab.drivers.slc.sim import SimulatedSlc


def test_a_key_has_one_handler() -> None:
    table: CommandTable[str] = CommandTable()
    table.handles("MODE")(lambda self: None)
    with pytest.raises(ValueError, match="'MODE' already handled"):
        table.handles("MODE")(lambda self: None)


@pytest.mark.parametrize(("cls", "known", "unknown"), [
    (SimulatedSlc, ["MODE", "?MODE", "NORMAL", "?CURRENT", "DEVICEINFO"], "FLASH"),
    (SimulatedAptStage, [Msg.HW_REQ_INFO, Msg.MOT_MOVE_ABSOLUTE, Msg.MOT_MOVE_STOP], 0x0002),
    (SimulatedCamera, [p.CMD_FIRMWARE, p.CMD_EXPOSURE, p.CMD_GET_IMAGE], 0x7F),
])
def test_each_simulator_has_a_command_table(cls: type, known: list, unknown: object) -> None:
    table = cls.commands
    assert isinstance(table, CommandTable)
    sim = object.__new__(cls)  # lookup needs no running simulator
    for key in known:
        handler = table.handler(sim, key)
        assert handler is not None and handler.__self__ is sim
    assert table.handler(sim, unknown) is None
