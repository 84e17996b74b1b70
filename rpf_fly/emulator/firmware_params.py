"""The fake firmware's parameter service (CRTP port 2; rpf_fly/emulator/fake_firmware.py): reads, writes,
set-by-name, extended types, defaults, and the persistent store that survives a reboot; a write acts on the
simulated drone as the firmware's does (the estimator's reset and initial state, the controller's gains, the
battery thresholds). Why apart: the parameters are how cflib configures a drone, with rules of their own.

:class:`FirmwareParams` is a part of :class:`~rpf_fly.emulator.fake_firmware.FakeFirmware`: it reads and sets the
firmware's attributes named in its body.
"""

from __future__ import annotations

import errno
import struct
from collections.abc import Callable

from .crtp import PORT_PARAM, Packet
from .fake_memory import MemoryTester
from .fake_toc import EXTENDED_TYPE_PERSISTENT, Toc, pack_value, unpack_value
from .fake_vehicle import Vehicle
from .firmware_tables import PARAM_DEFAULTS, PARAM_TOC
from .vehicle_firmware import CONTROLLER_PARAMS

PERSISTENT_NOT_STORED, PERSISTENT_STORED = 0, 1
"""`PARAM_PERSISTENT_NOT_STORED` / `_STORED` of param.h."""


class FirmwareParams:
    """The parameters' values, their writes and the persistent store."""

    vehicle: Vehicle
    memory_tester: MemoryTester
    _params: dict[str, float]
    _stored: dict[str, float]
    _toc: Callable[[int, Toc, bytes], list[Packet]]

    def _param(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if channel == 0:
            return self._toc(PORT_PARAM, PARAM_TOC, data)
        if channel == 3:
            return self._param_misc(data)
        ident = struct.unpack("<H", data[:2])[0]
        if ident >= len(PARAM_TOC):
            return [(PORT_PARAM, channel, data[:2] + bytes([errno.ENOENT]))]
        entry = PARAM_TOC.entries[ident]
        if channel == 1:
            return [(PORT_PARAM, 1, data[:2] + b"\0" + pack_value(entry.ctype, self._params[entry.full_name]))]
        if channel == 2:
            if entry.read_only:
                return []
            self._param_set(entry.full_name, unpack_value(entry.ctype, data[2:]))
            return [(PORT_PARAM, 2, data)]
        return []

    def _param_misc(self, data: bytes) -> list[Packet]:
        cmd = data[0]
        if cmd == 0:  # set by name: [0, group\0name\0, type, value]
            group_end = data.index(0, 1)
            name_end = data.index(0, group_end + 1)
            full_name = f"{data[1:group_end].decode()}.{data[group_end + 1 : name_end].decode()}"
            entry = PARAM_TOC.by_name.get(full_name)
            result = errno.ENOENT if entry is None else (errno.EACCES if entry.read_only else 0)
            if entry is not None and not entry.read_only:
                self._param_set(full_name, unpack_value(entry.ctype, data[name_end + 2 :]))
            return [(PORT_PARAM, 3, data[: name_end + 1] + bytes([result]))]
        ident = struct.unpack("<H", data[1:3])[0]
        entry = PARAM_TOC.entries[ident] if ident < len(PARAM_TOC) else None
        head = data[:3]
        if entry is None:
            return [(PORT_PARAM, 3, head + bytes([errno.ENOENT]))]
        default = pack_value(entry.ctype, PARAM_DEFAULTS[entry.full_name])
        if cmd in (2, 7):  # extended type (v1, v2)
            ext = EXTENDED_TYPE_PERSISTENT if entry.persistent else 0
            return [(PORT_PARAM, 3, head + (bytes([ext]) if cmd == 2 else bytes([0, ext])))]
        if cmd in (6, 8):  # default value (v1, v2)
            return [(PORT_PARAM, 3, head + (default if cmd == 6 else b"\0" + default))]
        if cmd == 4:  # persistent state (paramPersistentGetState): stored flag, default value, stored value
            stored = self._stored.get(entry.full_name)
            if stored is None:
                return [(PORT_PARAM, 3, head + bytes([PERSISTENT_NOT_STORED]) + default)]
            return [(PORT_PARAM, 3, head + bytes([PERSISTENT_STORED]) + default + pack_value(entry.ctype, stored))]
        if cmd == 3:  # persistent store: the current value, for persistent parameters only
            if not entry.persistent:
                return [(PORT_PARAM, 3, head + bytes([errno.ENOENT]))]
            self._stored[entry.full_name] = self._params[entry.full_name]
            return [(PORT_PARAM, 3, head + b"\0")]
        if cmd == 5:  # persistent clear
            self._stored.pop(entry.full_name, None)
            return [(PORT_PARAM, 3, head + b"\0")]
        return []

    def _param_set(self, full_name: str, value: float) -> None:
        v = self.vehicle
        self._params[full_name] = float(value)
        if full_name == "kalman.resetEstimation" and value:
            v.reset_estimator()
            self._params[full_name] = 0.0
        elif full_name == "stabilizer.stop":
            v.param_emergency_stop = bool(value)
        elif full_name == "locSrv.extPosStdDev":
            v.ext_pos_std_dev = float(value)
        elif full_name == "kalman.initialYaw":  # used at the next reset, as in the firmware
            v.initial_yaw = float(value)
        elif full_name.startswith("kalman.initial"):
            v.initial_estimate = (
                self._params["kalman.initialX"],
                self._params["kalman.initialY"],
                self._params["kalman.initialZ"],
            )
        elif full_name in CONTROLLER_PARAMS:
            v.set_controller_param(full_name, float(value))
        elif full_name == "pm.lowVoltage":
            v.low_voltage_v = float(value)
        elif full_name == "pm.criticalLowVoltage":
            v.critical_voltage_v = float(value)
        elif full_name == "memTst.resetW":
            self.memory_tester.reset_requested = bool(value)
