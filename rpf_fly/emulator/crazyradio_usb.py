"""The pyusb backend the emulated Crazyradios are plugged into: what cflib's ``Crazyradio`` reaches through pyusb.

Why a backend: cflib's ``cflib/drivers/crazyradio.py`` (``_find_devices``) asks ``libusb_package`` for pyusb's
libusb-1.0 backend and calls ``usb.core.find(idVendor=0x1915, idProduct=0x7777, backend=...)``; everything after
that (``set_configuration``, ``reset``, ``ctrl_transfer``, ``write``, ``read``, ``serial_number``,
``usb.util.dispose_resources``) goes through the backend's `usb.backend.IBackend` methods. `EmulatedBackend`
implements them for the dongles of one `crazyradio.plug`, so pyusb and cflib run unchanged above it.

The descriptors are the firmwares' (crazyradio-firmware ``usbDescriptor.c`` at tag 0.53 for the PA,
crazyradio2-firmware ``legacy_usb.c``, ``prj.conf`` and ``main.c`` for the 2.0): one configuration (value 1, bus
powered, 100 mA), one vendor-class interface with bulk endpoints 0x81 (IN) and 0x01 (OUT) of 64 bytes; strings 1
manufacturer, 2 product, 3 serial number (the PA's is string 0x1D). The dongles hang off one emulated bus, bus 1,
addresses 10, 11, ... in plug order.
"""

from __future__ import annotations

import array
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import usb.backend
import usb.core

from .crazyradio import IN_ENDPOINT, OUT_ENDPOINT, EmulatedCrazyradio, UsbFailure, no_device

VENDOR_ID, PRODUCT_ID = 0x1915, 0x7777
GET_STATUS, GET_DESCRIPTOR, GET_CONFIGURATION, SET_CONFIGURATION = 0x00, 0x06, 0x08, 0x09
DEVICE, CONFIGURATION, STRING = 1, 2, 3
LANGID_EN_US = 0x0409
BUS = 1
FIRST_ADDRESS = 10
SPEED_FULL = 2
"""pyusb's speed code for full speed (12 Mbit/s): both dongles are full-speed devices."""


@dataclass(frozen=True)
class Descriptor:
    """A descriptor as pyusb reads it: named fields (`usb.core` copies them onto its own objects)."""

    fields: dict[str, Any]

    def __getattr__(self, name: str) -> Any:
        try:
            return self.fields[name]
        except KeyError:
            raise AttributeError(name) from None


def serial_index(dongle: EmulatedCrazyradio) -> int:
    return 0x1D if dongle.radio.name == "crazyradio_pa" else 3


def device_descriptor(dongle: EmulatedCrazyradio) -> Descriptor:
    return Descriptor(
        dict(
            bLength=18,
            bDescriptorType=DEVICE,
            bcdUSB=0x0200,
            bDeviceClass=0,
            bDeviceSubClass=0,
            bDeviceProtocol=0,
            bMaxPacketSize0=64,
            idVendor=VENDOR_ID,
            idProduct=PRODUCT_ID,
            bcdDevice=dongle.radio.bcd_device,
            iManufacturer=1,
            iProduct=2,
            iSerialNumber=serial_index(dongle),
            bNumConfigurations=1,
            bus=BUS,
            address=FIRST_ADDRESS + dongle.index,
            port_number=dongle.index + 1,
            port_numbers=(dongle.index + 1,),
            speed=SPEED_FULL,
        )
    )


def _endpoints(dongle: EmulatedCrazyradio) -> list[Descriptor]:
    interval = dongle.radio.endpoint_interval
    ends = [
        Descriptor(
            dict(
                bLength=7,
                bDescriptorType=5,
                bEndpointAddress=address,
                bmAttributes=0x02,
                wMaxPacketSize=64,
                bInterval=interval,
                bRefresh=0,
                bSynchAddress=0,
                extra_descriptors=[],
            )
        )
        for address in (IN_ENDPOINT, OUT_ENDPOINT)
    ]
    return ends if dongle.radio.endpoints_in_first else ends[::-1]


def configuration_descriptor() -> Descriptor:
    return Descriptor(
        dict(
            bLength=9,
            bDescriptorType=CONFIGURATION,
            wTotalLength=32,
            bNumInterfaces=1,
            bConfigurationValue=1,
            iConfiguration=0,
            bmAttributes=0x80,
            bMaxPower=50,
            extra_descriptors=[],
        )
    )


def interface_descriptor(dongle: EmulatedCrazyradio) -> Descriptor:
    return Descriptor(
        dict(
            bLength=9,
            bDescriptorType=4,
            bInterfaceNumber=0,
            bAlternateSetting=0,
            bNumEndpoints=2,
            bInterfaceClass=0xFF,
            bInterfaceSubClass=dongle.radio.interface_subclass,
            bInterfaceProtocol=0,
            iInterface=0,
            extra_descriptors=[],
        )
    )


def _raw(desc: Descriptor, layout: tuple[tuple[str, int], ...]) -> bytes:
    return b"".join(int(desc.fields[name]).to_bytes(size, "little") for name, size in layout)


_DEVICE_LAYOUT = (
    ("bLength", 1),
    ("bDescriptorType", 1),
    ("bcdUSB", 2),
    ("bDeviceClass", 1),
    ("bDeviceSubClass", 1),
    ("bDeviceProtocol", 1),
    ("bMaxPacketSize0", 1),
    ("idVendor", 2),
    ("idProduct", 2),
    ("bcdDevice", 2),
    ("iManufacturer", 1),
    ("iProduct", 1),
    ("iSerialNumber", 1),
    ("bNumConfigurations", 1),
)
_CONFIG_LAYOUT = (
    ("bLength", 1),
    ("bDescriptorType", 1),
    ("wTotalLength", 2),
    ("bNumInterfaces", 1),
    ("bConfigurationValue", 1),
    ("iConfiguration", 1),
    ("bmAttributes", 1),
    ("bMaxPower", 1),
)
_INTERFACE_LAYOUT = (
    ("bLength", 1),
    ("bDescriptorType", 1),
    ("bInterfaceNumber", 1),
    ("bAlternateSetting", 1),
    ("bNumEndpoints", 1),
    ("bInterfaceClass", 1),
    ("bInterfaceSubClass", 1),
    ("bInterfaceProtocol", 1),
    ("iInterface", 1),
)
_ENDPOINT_LAYOUT = (
    ("bLength", 1),
    ("bDescriptorType", 1),
    ("bEndpointAddress", 1),
    ("bmAttributes", 1),
    ("wMaxPacketSize", 2),
    ("bInterval", 1),
)


def descriptor_bytes(dongle: EmulatedCrazyradio, kind: int, index: int) -> bytes | None:
    """A GET_DESCRIPTOR answer (None: the device stalls it)."""
    if kind == DEVICE:
        return _raw(device_descriptor(dongle), _DEVICE_LAYOUT)
    if kind == CONFIGURATION and index == 0:
        return (
            _raw(configuration_descriptor(), _CONFIG_LAYOUT)
            + _raw(interface_descriptor(dongle), _INTERFACE_LAYOUT)
            + b"".join(_raw(e, _ENDPOINT_LAYOUT) for e in _endpoints(dongle))
        )
    if kind == STRING:
        if index == 0:
            return bytes((4, STRING)) + LANGID_EN_US.to_bytes(2, "little")
        text = {1: dongle.radio.manufacturer, 2: dongle.radio.product, serial_index(dongle): dongle.serial}.get(index)
        if text is None:
            return None
        encoded = text.encode("utf-16-le")
        return bytes((2 + len(encoded), STRING)) + encoded
    return None


class Handle:
    """An open device (libusb's device handle): its dongle and claimed interfaces."""

    def __init__(self, dongle: EmulatedCrazyradio) -> None:
        self.dongle = dongle
        self.claimed: set[int] = set()
        self.open = True


def _usb_error(failure: UsbFailure) -> usb.core.USBError:
    cls = usb.core.USBTimeoutError if failure.libusb_code == -7 else usb.core.USBError
    return cls(failure.message, failure.libusb_code, failure.errno)


class EmulatedBackend(usb.backend.IBackend):
    """pyusb's backend interface over emulated Crazyradios (`crazyradio.EmulatedCrazyradio`). Device
    identifications are the dongles themselves; handles are `Handle`. A failed transfer raises pyusb's
    ``USBError`` with libusb's code and errno, as the libusb-1.0 backend does."""

    def __init__(self, dongles: list[EmulatedCrazyradio]) -> None:
        super().__init__()
        self.dongles = list(dongles)
        self._lock = threading.Lock()
        self._handles: set[Handle] = set()
        self._retired: Callable[[], None] | None = None

    def getter(self) -> EmulatedBackend:
        """Stands in for ``libusb_package.get_libusb1_backend``."""
        return self

    def retire(self, on_last_close: Callable[[], None]) -> None:
        """No longer plugged in (`crazyradio.unplug`): call ``on_last_close`` once no handle is open."""
        with self._lock:
            self._retired = on_last_close
            done = not self._handles
        if done:
            on_last_close()

    # Enumeration and descriptors ------------------------------------------------------------------------------

    def enumerate_devices(self) -> Iterator[EmulatedCrazyradio]:
        return iter([d for d in self.dongles if d.present])

    def get_parent(self, dev: EmulatedCrazyradio) -> None:
        return None

    def get_device_descriptor(self, dev: EmulatedCrazyradio) -> Descriptor:
        return device_descriptor(dev)

    def get_configuration_descriptor(self, dev: EmulatedCrazyradio, config: int) -> Descriptor:
        if config != 0:
            raise IndexError(config)
        return configuration_descriptor()

    def get_interface_descriptor(self, dev: EmulatedCrazyradio, intf: int, alt: int, config: int) -> Descriptor:
        if config != 0 or intf != 0 or alt != 0:
            raise IndexError((intf, alt, config))
        return interface_descriptor(dev)

    def get_endpoint_descriptor(self, dev: EmulatedCrazyradio, ep: int, intf: int, alt: int, config: int) -> Descriptor:
        if config != 0 or intf != 0 or alt != 0 or not 0 <= ep < 2:
            raise IndexError((ep, intf, alt, config))
        return _endpoints(dev)[ep]

    # Handles ----------------------------------------------------------------------------------------------------

    def open_device(self, dev: EmulatedCrazyradio) -> Handle:
        if not dev.present:
            raise _usb_error(no_device())
        handle = Handle(dev)
        with self._lock:
            self._handles.add(handle)
        return handle

    def close_device(self, dev_handle: Handle) -> None:
        dev_handle.open = False
        with self._lock:
            self._handles.discard(dev_handle)
            retired = self._retired if not self._handles else None
            if retired is not None:
                self._retired = None
        if retired is not None:
            retired()

    def set_configuration(self, dev_handle: Handle, config_value: int) -> None:
        self._standard(dev_handle)
        if config_value not in (0, 1):
            raise _usb_error(UsbFailure(-9, 32, "Pipe error"))
        dev_handle.dongle.configuration = config_value

    def get_configuration(self, dev_handle: Handle) -> int:
        return int(dev_handle.dongle.configuration)

    def set_interface_altsetting(self, dev_handle: Handle, intf: int, altsetting: int) -> None:
        self._standard(dev_handle)
        if intf != 0 or altsetting != 0:
            raise _usb_error(UsbFailure(-9, 32, "Pipe error"))

    def claim_interface(self, dev_handle: Handle, intf: int) -> None:
        self._alive(dev_handle)
        if intf != 0:
            raise _usb_error(UsbFailure(-5, 2, "Entity not found"))
        dev_handle.claimed.add(intf)

    def release_interface(self, dev_handle: Handle, intf: int) -> None:
        dev_handle.claimed.discard(intf)

    def reset_device(self, dev_handle: Handle) -> None:
        self._call(dev_handle.dongle.reset)

    def clear_halt(self, dev_handle: Handle, ep: int) -> None:
        self._standard(dev_handle)

    def is_kernel_driver_active(self, dev_handle: Handle, intf: int) -> bool:
        return False

    def detach_kernel_driver(self, dev_handle: Handle, intf: int) -> None:
        return None

    def attach_kernel_driver(self, dev_handle: Handle, intf: int) -> None:
        return None

    # Transfers --------------------------------------------------------------------------------------------------

    def bulk_write(self, dev_handle: Handle, ep: int, intf: int, data: array.array, timeout: int) -> int:
        self._alive(dev_handle, intf)
        return int(self._call(dev_handle.dongle.bulk_out, ep, data.tobytes(), timeout))

    def bulk_read(self, dev_handle: Handle, ep: int, intf: int, buff: array.array, timeout: int) -> int:
        self._alive(dev_handle, intf)
        answer = self._call(dev_handle.dongle.bulk_in, ep, len(buff) * buff.itemsize, timeout)
        view = memoryview(buff).cast("B")
        view[: len(answer)] = answer
        return len(answer)

    def ctrl_transfer(
        self,
        dev_handle: Handle,
        bmRequestType: int,
        bRequest: int,
        wValue: int,
        wIndex: int,
        data: array.array,
        timeout: int,
    ) -> int:
        self._alive(dev_handle)
        dongle = dev_handle.dongle
        size = len(data) * data.itemsize
        if bmRequestType & 0x60 == 0x40:  # vendor
            out = bytes(data.tobytes()) if not bmRequestType & 0x80 else b""
            result = self._call(dongle.vendor_request, bmRequestType, bRequest, wValue, wIndex, out, size)
            if isinstance(result, bytes):
                memoryview(data).cast("B")[: len(result)] = result
                return len(result)
            return int(result)
        self._call(dongle.standard_request)
        if bmRequestType == 0x80 and bRequest == GET_DESCRIPTOR:
            answer = descriptor_bytes(dongle, wValue >> 8, wValue & 0xFF)
            if answer is None:
                raise _usb_error(UsbFailure(-9, 32, "Pipe error"))
            answer = answer[:size]
            memoryview(data).cast("B")[: len(answer)] = answer
            return len(answer)
        if bmRequestType == 0x80 and bRequest == GET_CONFIGURATION and size >= 1:
            memoryview(data).cast("B")[0] = dongle.configuration
            return 1
        if bmRequestType == 0x80 and bRequest == GET_STATUS and size >= 2:
            memoryview(data).cast("B")[:2] = b"\x00\x00"
            return 2
        if bmRequestType == 0x00 and bRequest == SET_CONFIGURATION:
            dongle.configuration = wValue & 0xFF
            return 0
        raise _usb_error(UsbFailure(-9, 32, "Pipe error"))

    # Helpers ----------------------------------------------------------------------------------------------------

    def _standard(self, dev_handle: Handle) -> None:
        self._alive(dev_handle)
        self._call(dev_handle.dongle.standard_request)

    @staticmethod
    def _alive(dev_handle: Handle, intf: int | None = None) -> None:
        if not dev_handle.open or not dev_handle.dongle.present:
            raise _usb_error(no_device())
        if intf is not None and intf not in dev_handle.claimed:
            raise _usb_error(UsbFailure(-5, 2, "Entity not found"))

    @staticmethod
    def _call(fn: Callable[..., Any], *args: Any) -> Any:
        try:
            return fn(*args)
        except UsbFailure as failure:
            raise _usb_error(failure) from None
