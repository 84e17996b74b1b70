"""Are the Crazyradios a mission's ``radio://`` URIs need plugged in? Asked on USB before any link is tried.

cflib finds a dongle only when a link opens (``RadioDriver.connect`` -> ``Crazyradio(devid)``): with none plugged in,
every drone's link fails on its own thread, and cflib logs a traceback for each (``Crazyflie.open_link``). The
same USB lookup cflib's driver makes (``cflib.drivers.crazyradio._find_devices``: vendor 0x1915, product 0x7777,
cflib 0.1.34) answers the question once, before anything connects. A URI's dongle is its number
(``radio://0/...``: the first dongle found) or a serial number (``radio://<serial>/...``), as cflib reads it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any
from urllib.parse import urlparse

NO_RADIO = "no Crazyradio found on USB: plug one in, or fly with --dry-run"


def find_radios() -> Sequence[Any]:
    """The Crazyradios on USB (pyusb devices), by cflib's own lookup. Raises when USB cannot be asked (no libusb)."""
    from cflib.drivers import crazyradio

    find = getattr(crazyradio, "_find_devices", None)
    if find is None:  # a cflib without the private lookup: its public one (which also reads each serial number)
        return crazyradio.get_serials()
    return list(find())


def _serial(device: Any) -> str:
    return str(device if isinstance(device, str) else device.serial_number).upper()


def radio_problem(uris: Iterable[str], find: Callable[[], Sequence[Any]] = find_radios) -> str | None:
    """None when every ``radio://`` URI of ``uris`` has its Crazyradio on USB (or there is no radio URI); otherwise
    one line saying what is missing."""
    radio = [u for u in uris if u.startswith("radio://")]
    if not radio:
        return None
    try:
        devices = find()
    except Exception as exc:  # noqa: BLE001 - no libusb backend, USB not readable: say so instead of a traceback
        return (
            f"cannot look for a Crazyradio on USB ({type(exc).__name__}: {exc}): plug one in and check libusb, "
            "or fly with --dry-run"
        )
    if not devices:
        return NO_RADIO
    serials: list[str] | None = None
    for uri in radio:
        dongle = urlparse(uri).netloc
        if len(dongle) < 10 and dongle.isdigit():
            if int(dongle) >= len(devices):
                return (
                    f"{uri} needs Crazyradio number {int(dongle)} (counting from 0), but {len(devices)} "
                    f"found on USB: plug in another, or fly with --dry-run"
                )
            continue
        if serials is None:
            try:
                serials = [_serial(d) for d in devices]
            except Exception as exc:  # noqa: BLE001 - reading a serial number needs access to the device
                return f"{uri}: cannot read the serial numbers of the Crazyradios on USB ({exc})"
        if dongle.upper() not in serials:
            return f"{uri}: no Crazyradio with serial {dongle} on USB (found {', '.join(serials)})"
    return None
