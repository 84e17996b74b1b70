"""The fake firmware's flight services (rpf_fly/emulator/fake_firmware.py): the commander (CRTP port 3, the
legacy RPYT setpoint), the generic commander (7: setpoints, notify-setpoint-stop), the high-level commander (8),
localization (6: extpos, extpose, packed extpos, the emergency stop and its watchdog) and the supervisor (9:
arming, crash recovery, its bits). Why apart: these decode what flies the drone; the vehicle acts on them.

:class:`FirmwareFlight` is a part of :class:`~rpf_fly.emulator.fake_firmware.FakeFirmware`: it reads and sets the
firmware's attributes named in its body.
"""

from __future__ import annotations

import struct
from collections.abc import Callable

from .crtp import PORT_SETPOINT_HL, PORT_SUPERVISOR, Packet
from .fake_setpoint import decode_generic, decode_rpyt
from .fake_vehicle import Vehicle

_PACKED_ITEM = struct.Struct("<Bhhh")
"""One item of a packed external position (crazyflie-firmware crtp_localization_service.c lines 105-111,
``extPositionPackedItem``; read by ``extPositionPackedHandler``, lines 350-369)."""


class FirmwareFlight:
    """The setpoints, external positions and supervisor commands a drone is flown by."""

    vehicle: Vehicle
    packed_id: int
    supervisor_bits: Callable[[], int]

    def _commander(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if channel != 0:
            return []
        setpoint, self.vehicle.rpyt_thrust_locked = decode_rpyt(data, now_s, self.vehicle.rpyt_thrust_locked)
        if setpoint is not None:
            self.vehicle.crtp_setpoint(setpoint, now_s)
        return []

    def _commander_generic(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if channel == 0:
            setpoint = decode_generic(data, now_s, self.vehicle.estimate_yaw)
            if setpoint is not None:
                self.vehicle.crtp_setpoint(setpoint, now_s)
        elif channel == 1 and data and data[0] == 0:
            remain_ms = struct.unpack("<I", data[1:5])[0] if len(data) >= 5 else 0
            self.vehicle.notify_setpoint_stop(remain_ms)
        return []

    def _high_level(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        answer = self.vehicle.hl.handle(data, now_s)
        return [(PORT_SETPOINT_HL, channel, answer)] if answer else []

    def _localization(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        v = self.vehicle
        if channel == 0:
            v.external_position(struct.unpack("<fff", data[:12]), now_s)
        elif channel == 2:  # EXT_POSITION_PACKED: size / 7 items of id, int16 mm x, y, z; its own id only
            for k in range(len(data) // _PACKED_ITEM.size):  # (others go to peer localization: not simulated)
                ident, x, y, z = _PACKED_ITEM.unpack_from(data, k * _PACKED_ITEM.size)
                if ident == self.packed_id:
                    v.external_position((x / 1000.0, y / 1000.0, z / 1000.0), now_s)
        elif channel == 1 and data:
            kind = data[0]
            if kind == 8:
                x, y, z, qx, qy, qz, qw = struct.unpack("<fffffff", data[1:29])
                v.external_pose((x, y, z), (qx, qy, qz, qw), now_s)
            elif kind == 3:
                v.supervisor.request_emergency_stop()
            elif kind == 4:
                v.supervisor.notify_emergency_stop_watchdog(now_s)
        return []

    def _supervisor(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if not data:
            return []
        sup = self.vehicle.supervisor
        cmd = data[0]
        if channel == 0:
            bits = self.supervisor_bits()
            if cmd == 0x0C:
                return [(PORT_SUPERVISOR, 0, bytes([0x80 | cmd]) + struct.pack("<H", bits))]
            if 0x01 <= cmd <= 0x0B:
                return [(PORT_SUPERVISOR, 0, bytes([0x80 | cmd, (bits >> (cmd - 1)) & 1]))]
            return []
        if channel == 1:
            if cmd == 0x01:
                success = sup.request_arming(bool(data[1]) if len(data) > 1 else True)
                return [(PORT_SUPERVISOR, 1, bytes([0x81, int(success), int(sup.armed)]))]
            if (
                cmd == 0x02
            ):  # crash recovery: refused while tumbled (the firmware's rule); a crash here tumbles for good
                recovered = not sup.tumbled
                return [(PORT_SUPERVISOR, 1, bytes([0x82, int(recovered), int(recovered)]))]
            if cmd == 0x03:
                sup.request_emergency_stop()
            elif cmd == 0x04:
                sup.notify_emergency_stop_watchdog(now_s)
        return []
