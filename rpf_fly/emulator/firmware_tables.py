"""The fake firmware's log and parameter tables (rpf_fly/emulator/fake_firmware.py): each log variable with its C
type and how it reads the simulated drone, each parameter with its type, default and flags, and their TOCs. Why
apart: the tables are what cflib sees of the firmware (names, types, defaults, checked against crazyflie-firmware);
the services that answer with them are code.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING

from .cf_controller import CfGains
from .fake_setpoint import AxisMode
from .fake_toc import Toc, make_toc
from .fake_vehicle import Vehicle
from .vehicle_figures import HOVER_THRUST

if TYPE_CHECKING:
    from .fake_firmware import FakeFirmware


def _thrust(vehicle: Vehicle) -> float:
    """`stabilizer.thrust`: an attitude mode's raw thrust, else the hover thrust while the motors spin."""
    if not vehicle.motors_on:
        return 0.0
    setpoint = vehicle.control_setpoint
    return float(setpoint.thrust) if setpoint.modes[2] is AxisMode.DISABLE else float(HOVER_THRUST)


LOG_VARIABLES: tuple[tuple[str, str, Callable[[FakeFirmware], float]], ...] = (
    ("stateEstimate.x", "float", lambda f: f.vehicle.estimate[0]),
    ("stateEstimate.y", "float", lambda f: f.vehicle.estimate[1]),
    ("stateEstimate.z", "float", lambda f: f.vehicle.estimate[2]),
    ("stateEstimate.vx", "float", lambda f: f.vehicle.estimate_velocity[0]),
    ("stateEstimate.vy", "float", lambda f: f.vehicle.estimate_velocity[1]),
    ("stateEstimate.vz", "float", lambda f: f.vehicle.estimate_velocity[2]),
    ("stateEstimate.roll", "float", lambda f: 0.0),
    ("stateEstimate.pitch", "float", lambda f: 0.0),
    ("stateEstimate.yaw", "float", lambda f: math.degrees(f.vehicle.estimate_yaw)),
    ("pm.vbat", "float", lambda f: f.vehicle.battery.vbat_v),
    ("pm.state", "int8_t", lambda f: f.vehicle.battery.pm_state),
    ("pm.batteryLevel", "uint8_t", lambda f: min(max((f.vehicle.battery.vbat_v - 3.0) / 1.2, 0.0), 1.0) * 100.0),
    ("supervisor.info", "uint16_t", lambda f: f.supervisor_bits()),
    ("sys.canfly", "uint8_t", lambda f: f.vehicle.supervisor.motors_allowed),
    ("sys.isFlying", "uint8_t", lambda f: f.vehicle.supervisor.is_flying),
    ("sys.isTumbled", "uint8_t", lambda f: f.vehicle.supervisor.tumbled),
    ("kalman.stateX", "float", lambda f: f.vehicle.estimate[0]),
    ("kalman.stateY", "float", lambda f: f.vehicle.estimate[1]),
    ("kalman.stateZ", "float", lambda f: f.vehicle.estimate[2]),
    ("kalman.varPX", "float", lambda f: f.vehicle.variance_m2),
    ("kalman.varPY", "float", lambda f: f.vehicle.variance_m2),
    ("kalman.varPZ", "float", lambda f: f.vehicle.variance_m2),
    ("radio.rssi", "uint8_t", lambda f: f.rssi),
    ("radio.isConnected", "uint8_t", lambda f: 1),
    ("ctrltarget.x", "float", lambda f: f.vehicle.control_setpoint.position[0]),
    ("ctrltarget.y", "float", lambda f: f.vehicle.control_setpoint.position[1]),
    ("ctrltarget.z", "float", lambda f: f.vehicle.control_setpoint.position[2]),
    ("ctrltarget.yaw", "float", lambda f: f.vehicle.control_setpoint.yaw_deg),
    # the compressed groups (stabilizer.c: mm and mm/s as int16, the C cast truncating toward zero): a status log
    # block fits the estimate and the controller's target in one 26-byte packet
    ("stateEstimateZ.x", "int16_t", lambda f: f.vehicle.estimate[0] * 1000.0),
    ("stateEstimateZ.y", "int16_t", lambda f: f.vehicle.estimate[1] * 1000.0),
    ("stateEstimateZ.z", "int16_t", lambda f: f.vehicle.estimate[2] * 1000.0),
    ("stateEstimateZ.vx", "int16_t", lambda f: f.vehicle.estimate_velocity[0] * 1000.0),
    ("stateEstimateZ.vy", "int16_t", lambda f: f.vehicle.estimate_velocity[1] * 1000.0),
    ("stateEstimateZ.vz", "int16_t", lambda f: f.vehicle.estimate_velocity[2] * 1000.0),
    ("ctrltargetZ.x", "int16_t", lambda f: f.vehicle.control_setpoint.position[0] * 1000.0),
    ("ctrltargetZ.y", "int16_t", lambda f: f.vehicle.control_setpoint.position[1] * 1000.0),
    ("ctrltargetZ.z", "int16_t", lambda f: f.vehicle.control_setpoint.position[2] * 1000.0),
    ("ctrltargetZ.vx", "int16_t", lambda f: f.vehicle.control_setpoint.velocity[0] * 1000.0),
    ("ctrltargetZ.vy", "int16_t", lambda f: f.vehicle.control_setpoint.velocity[1] * 1000.0),
    ("ctrltargetZ.vz", "int16_t", lambda f: f.vehicle.control_setpoint.velocity[2] * 1000.0),
    ("stabilizer.roll", "float", lambda f: f.vehicle.attitude_deg[0]),
    ("stabilizer.pitch", "float", lambda f: f.vehicle.attitude_deg[1]),
    ("stabilizer.yaw", "float", lambda f: math.degrees(f.vehicle.estimate_yaw)),
    ("stabilizer.thrust", "float", lambda f: _thrust(f.vehicle)),
    ("memTst.errCntW", "uint32_t", lambda f: f.memory_tester.write_errors),
)

_CONTROLLER_PARAM_TYPES: Mapping[str, str] = MappingProxyType(
    {"posCtlPid.thrustBase": "uint16_t", "posCtlPid.thrustMin": "uint16_t"}
)
"""The controller parameters that are not floats (`position_controller_pid.c:521-603`: PARAM_UINT16)."""
_CONTROLLER_PARAMS: tuple[tuple[str, str, float, bool, bool], ...] = tuple(
    (name, _CONTROLLER_PARAM_TYPES.get(name, "float"), default, False, True)
    for name, default in CfGains().params().items()
)
"""The PID controller's gains and limits under their firmware names, types and defaults (cf_controller.CfGains,
checked against the PARAM_GROUP blocks of `position_controller_pid.c:462-603` (velCtlPid, posCtlPid) and
`attitude_pid_controller.c:318-450` (pid_attitude, pid_rate) at crazyflie-firmware 2a18fc29: every one
PARAM_PERSISTENT, floats but posCtlPid.thrustBase and thrustMin, uint16). Written, they act on the simulated
drone's controller at once (`Vehicle.set_controller_param`: all of them with the "firmware" dynamics, the velocity
limits with the first-order one); the filter switches and cut-offs of those groups are not here (not modelled)."""

# (name, ctype, default, read_only, persistent). Names and defaults of the firmware's groups that cflib programs and
# Bitcraze's examples touch (crazyflie-firmware's param definitions and platform defaults), the controller's with
# them (`_CONTROLLER_PARAMS`).
_PARAMS: tuple[tuple[str, str, float, bool, bool], ...] = (
    ("stabilizer.estimator", "uint8_t", 0, False, False),
    ("stabilizer.controller", "uint8_t", 0, False, False),
    ("stabilizer.stop", "uint8_t", 0, False, False),
    ("commander.enHighLevel", "uint8_t", 0, False, False),
    ("locSrv.extPosStdDev", "float", 0.01, False, False),
    ("locSrv.extQuatStdDev", "float", 4.5e-3, False, False),
    ("kalman.resetEstimation", "uint8_t", 0, False, False),
    ("kalman.initialX", "float", 0.0, False, False),
    ("kalman.initialY", "float", 0.0, False, False),
    ("kalman.initialZ", "float", 0.0, False, False),
    ("kalman.initialYaw", "float", 0.0, False, False),
    ("hlCommander.vtoff", "float", 0.5, False, False),
    ("hlCommander.vland", "float", 0.5, False, False),
    ("pm.lowVoltage", "float", 3.2, False, True),
    ("pm.criticalLowVoltage", "float", 3.0, False, True),
    ("led.bitmask", "uint8_t", 0, False, False),
    *_CONTROLLER_PARAMS,
    ("memTst.resetW", "uint8_t", 0, False, False),
    # deck drivers of the default build register their parameters whether or not their deck is there
    # (ledring12.c: effect 6, CONFIG_DECK_LEDRING_DEFAULT_EFFECT, neffect 18; activeMarkerDeck.c: ids 1 3 4 2, mode 3
    # Qualisys); deck.bc*: 1 when that deck was found and initialised, so 0 on a deckless drone
    ("ring.effect", "uint8_t", 6, False, True),
    ("ring.neffect", "uint32_t", 18, True, False),
    ("activeMarker.front", "uint8_t", 1, False, True),
    ("activeMarker.back", "uint8_t", 3, False, True),
    ("activeMarker.left", "uint8_t", 4, False, True),
    ("activeMarker.right", "uint8_t", 2, False, True),
    ("activeMarker.mode", "uint8_t", 3, False, True),
    ("activeMarker.poll", "uint8_t", 0, False, False),
    *(
        (f"deck.{flag}", "uint8_t", 0, True, False)
        for flag in (
            "bcActiveMarker",
            "bcAI",
            "bcBuzzer",
            "bcDWM1000",
            "bcFlow",
            "bcFlow2",
            "bcLedRing",
            "bcLighthouse4",
            "bcLoco",
            "bcMultiranger",
            "bcUSD",
            "bcZRanger",
            "bcZRanger2",
        )
    ),
    # system.c: the MCU's flash size in kB (STM32F405: 1024) and unique id
    ("cpu.flash", "uint16_t", 1024, True, False),
    ("cpu.id0", "uint32_t", 0x0033_0047, True, False),
    ("cpu.id1", "uint32_t", 0x3236_5104, True, False),
    ("cpu.id2", "uint32_t", 0x3038_3533, True, False),
    ("firmware.revision0", "uint32_t", 0x2026_0800, True, False),
    ("firmware.modified", "uint8_t", 0, True, False),
)

LOG_TOC: Toc = make_toc([(name, ctype) for name, ctype, _ in LOG_VARIABLES], is_param=False)
PARAM_TOC: Toc = make_toc([(n, c, ro, pers) for n, c, _, ro, pers in _PARAMS], is_param=True)
LOG_GETTERS = tuple(getter for _, _, getter in LOG_VARIABLES)
PARAM_DEFAULTS: Mapping[str, float] = MappingProxyType({name: float(default) for name, _, default, _, _ in _PARAMS})
