"""CRTP as the fake firmware speaks it: the ports, as crazyflie-firmware's crtp.h numbers them, and the packet
tuple the firmware, its services and the fake links pass. Why apart: the firmware's services each answer on their
own port, and the links carry the packets without needing the firmware.
"""

from __future__ import annotations

Packet = tuple[int, int, bytes]
"""(port, channel, payload) of one CRTP packet."""

PORT_CONSOLE, PORT_PARAM, PORT_COMMANDER, PORT_MEM, PORT_LOG = 0, 2, 3, 4, 5
PORT_LOCALIZATION, PORT_COMMANDER_GENERIC, PORT_SETPOINT_HL, PORT_SUPERVISOR = 6, 7, 8, 9
PORT_PLATFORM, PORT_LINK = 13, 15
