"""A vehicle profile: one drone's calibrated closed loop as a YAML file, for a dry run to fly that drone.

Why a file of firmware parameters: the simulated drone of a dry run flies the firmware's cascade (docs/dynamics.md)
and takes its gains from its TOC under the firmware's names, so a profile is what a simulated Crazyflie would keep
in its EEPROM (persistent parameters, applied at boot) plus how late and how noisy its mocap poses are. A mission
names it with ``dry_run: {dynamics: firmware, vehicle: PROFILE.yaml}`` (docs/mission-format.md).

The file (written by `profile_text`, read by `load_profile`)::

    format: 1
    drone: cf1                          # whose flight it was fitted on
    source: {file: ..., kind: log, origin: dry-run, window_s: 8.1, samples: 811}
    params: {posCtlPid.xKp: 1.41, ...}  # firmware parameters (cf_controller.CfGains' names), set in the TOC
    mocap: {latency_s: 0.0035, latency_from: truth, noise_m: 0.0005}
    fit: {...}                          # what the fit found (residuals, delay, gains not identified): for people

``params`` and ``mocap`` act; the rest says where the profile came from. A parameter the simulated firmware does
not have, a value that is not a finite number >= 0, or an unknown key is refused with one line.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

FORMAT = 1
TOP_KEYS = ("format", "drone", "source", "params", "mocap", "fit")
MOCAP_KEYS = ("latency_s", "latency_from", "noise_m")
UINT16_PARAMS = ("posCtlPid.thrustBase", "posCtlPid.thrustMin")
MAX_LATENCY_S = 2.0
"""The longest mocap latency the dry run's simulated mocap serves (`world_process.MOCAP_HISTORY_S`)."""
MAX_NOISE_M = 0.05
EMULATOR_MOCAP_LATENCY_S = 0.006
"""How late a dry run's own mocap poses are logged: the shift that lays a log's ``/mocap`` poses on its ``/truth``
(`fit.mocap_against_truth`), 2 to 9.5 ms by the phase between the world's 10 ms steps and the NatNet emulator's
frames (fixed for a run), 6.2 ms on average over 40 dry-run logs of this project's tests (docs/dynamics.md,
"Calibrating a vehicle profile"). A profile's latency beyond it is added to the simulated mocap."""


class ProfileError(ValueError):
    """A profile that cannot be used; the message is one line: the field and what is wrong."""


@dataclass(frozen=True)
class VehicleProfile:
    """What a dry run takes from a profile (module doc)."""

    path: Path | None
    drone: str
    params: tuple[tuple[str, float], ...]
    """Firmware parameters by name, in the file's order."""
    mocap_latency_s: float | None = None
    mocap_noise_m: float | None = None

    def mocap_delay_s(self, rate_hz: float) -> float:
        """The delay to give the simulated mocap (`SimulatedBodies.mocap_delay`) for this profile's latency: the
        part beyond the emulator's own (`EMULATOR_MOCAP_LATENCY_S`) in whole frames at ``rate_hz`` (the simulated
        mocap serves an earlier frame's poses), as the half-frame that selects that many frames back; 0 for none."""
        if self.mocap_latency_s is None:
            return 0.0
        period = 1.0 / rate_hz
        frames = round((self.mocap_latency_s - EMULATOR_MOCAP_LATENCY_S) / period)
        return (frames - 0.5) * period if frames >= 1 else 0.0


def _number(value: Any, where: str, lo: float = 0.0, hi: float = math.inf) -> float:
    """``value`` as a finite number in [lo, hi] (YAML's booleans are not numbers); `ProfileError` naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ProfileError(f"{where}: expected a finite number, got {value!r}")
    if not lo <= value <= hi:
        span = f"at least {lo:g}" if hi == math.inf else f"in [{lo:g}, {hi:g}]"
        raise ProfileError(f"{where}: expected a number {span}, got {value:g}")
    return float(value)


def parse_profile(doc: Any, path: Path | None = None) -> VehicleProfile:
    """A profile from its parsed YAML ``doc`` (module doc); `ProfileError` names the field at fault."""
    from rpf_fly.emulator.cf_controller import PARAM_NAMES

    if not isinstance(doc, dict):
        raise ProfileError(f"expected a vehicle profile (a mapping with params and mocap), got {type(doc).__name__}")
    unknown = [str(k) for k in doc if k not in TOP_KEYS]
    if unknown:
        raise ProfileError(f"{unknown[0]}: unknown key (a profile has {', '.join(TOP_KEYS)})")
    if "format" in doc and doc["format"] != FORMAT:
        raise ProfileError(f"format: expected {FORMAT}, got {doc['format']!r}")
    if "params" not in doc:
        raise ProfileError("params: missing (the firmware parameters the profile sets)")
    params = doc["params"]
    if params is None:
        params = {}
    if not isinstance(params, dict):
        raise ProfileError(f"params: expected a mapping of firmware parameters, got {type(params).__name__}")
    known = set(PARAM_NAMES)
    out = []
    for name, value in params.items():
        if name not in known:
            raise ProfileError(
                f"params.{name}: not a parameter of the simulated firmware's controller "
                "(posCtlPid.*, velCtlPid.*, pid_attitude.*, pid_rate.*: docs/dynamics.md)"
            )
        hi = 65535.0 if name in UINT16_PARAMS else math.inf
        out.append((str(name), _number(value, f"params.{name}", 0.0, hi)))
    latency = noise = None
    mocap = doc.get("mocap")
    if mocap is not None:
        if not isinstance(mocap, dict):
            raise ProfileError(f"mocap: expected a mapping ({', '.join(MOCAP_KEYS)}), got {type(mocap).__name__}")
        bad = [str(k) for k in mocap if k not in MOCAP_KEYS]
        if bad:
            raise ProfileError(f"mocap.{bad[0]}: unknown key (mocap has {', '.join(MOCAP_KEYS)})")
        if "latency_s" in mocap:
            latency = _number(mocap["latency_s"], "mocap.latency_s", 0.0, MAX_LATENCY_S)
        if "noise_m" in mocap:
            noise = _number(mocap["noise_m"], "mocap.noise_m", 0.0, MAX_NOISE_M)
    drone = doc.get("drone", "")
    return VehicleProfile(
        path=path,
        drone=str(drone) if drone is not None else "",
        params=tuple(out),
        mocap_latency_s=latency,
        mocap_noise_m=noise,
    )


def load_profile(path: Path) -> VehicleProfile:
    """The profile in ``path``; `ProfileError` (one line: the file, the field, what is wrong) otherwise."""
    import yaml

    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ProfileError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ProfileError(f"{path}: cannot be read ({getattr(err, 'strerror', None) or err})") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as err:
        first = " ".join(str(err).split())[:160]
        raise ProfileError(f"{path}: not YAML ({first})") from None
    try:
        return parse_profile(doc, Path(path))
    except ProfileError as err:
        raise ProfileError(f"{path}: {err}") from None


def _plain(value: Any) -> Any:
    """YAML-friendly: floats rounded to 6 significant digits, tuples as lists."""
    if isinstance(value, float):
        return float(f"{value:.6g}")
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def profile_text(
    drone: str,
    params: Mapping[str, float],
    *,
    source: Mapping[str, Any],
    mocap: Mapping[str, Any],
    fit: Mapping[str, Any],
) -> str:
    """The profile file's text (module doc), a comment line first saying what it is and how it was made."""
    import yaml

    doc = {
        "format": FORMAT,
        "drone": drone,
        "source": _plain(source),
        "params": _plain(dict(params)),
        "mocap": _plain(dict(mocap)),
        "fit": _plain(dict(fit)),
    }
    head = (
        "# rpf-fly vehicle profile: the firmware gains and mocap figures under which the simulated drone flies\n"
        '# as this drone flew (rpf-fly calibrate; docs/dynamics.md, "Calibrating a vehicle profile"). A mission\n'
        "# uses it with dry_run: {dynamics: firmware, vehicle: THIS_FILE}.\n"
    )
    return head + yaml.safe_dump(doc, sort_keys=False, default_flow_style=False, width=120)
