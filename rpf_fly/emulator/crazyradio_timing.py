"""What an emulated Crazyradio is and what each of its operations costs: one table of figures per dongle type.

Why one table: the emulated dongle (`crazyradio.py`) spends these times in the calling thread, so cflib's own radio
driver meets a dongle as slow as a real one; the tests and docs/radio.md ("The emulated Crazyradio") derive their
bounds from the same figures. Each figure says where it comes from or that it is an estimate.

Sources (facts only, read for this module):
- crazyradio-firmware (Crazyradio PA, nRF24LU1+) at 92dd1d8: its USB protocol page
  ``functional-areas/usb_radio_protocol.md`` (the USB protocol, "the USB setup transaction ... takes about 1ms"),
  ``firmware/src/main.c`` (``handleUsbVendorSetup``, ``legacyRun``: the status byte), ``firmware/src/radio.c``
  (``radioUpdateRetr``: the ARD table by ACK payload length, ``radioSetChannel``), ``firmware/src/usbDescriptor.c`` at
  tag 0.53 (bcdDevice 0x0053);
- the nRF24LU1+ Product Specification v1.0 (in that repository, ``docs/images/nrf24lu1p_1_0.pdf``): section 6.4
  (ARD "from the end of a transmitted packet to when a retransmit starts", table 17, ARD 500 us for any ACK
  payload at 1 and 2 Mbps), table 18 (T_OA = (8 * (1 preamble + 5 address + payload + 2 CRC) + 9) / rate,
  T_ESB = T_UL + 2 Tstby2a + T_OA + T_ACK + T_IRQ, T_IRQ 8.2 us at 1 Mbps and 6.0 us at 2 Mbps), Tstby2a 130 us;
- crazyradio2-firmware (Crazyradio 2.0, nRF52840) at c0d2c17: ``src/legacy_usb.c`` (vendor requests, channels
  above 100 and 250 kbps never acknowledged, the status byte), ``src/esb.c`` (``esb_send_packet``: ARC attempts, a
  500 us acknowledgement timeout after each transmission, ARD ignored), ``VERSION`` 5.4 and ``src/main.c``
  (bcdDevice = the firmware version in BCD, 0x0504);
- github.com/bitcraze/crazyradio2-firmware/issues/9 (a Crazyradio 2.0 under libusb): a vendor control transfer
  about 2.5 ms, a bulk write and read together about 0.7 ms, so about 300 packets/s when every packet needs one
  setup call; .../issues/23: one link without setup calls, about 1270 packets/s;
- USB 2.0 specification 7.1.7.5: reset signalling lasts at least 10 ms.
"""

from __future__ import annotations

from dataclasses import dataclass, field

DR_250K, DR_1M, DR_2M = 0, 1, 2
"""Data rate codes of SET_DATA_RATE (cflib ``Crazyradio.DR_*``)."""

RATE_BPS = {DR_250K: 250_000, DR_1M: 1_000_000, DR_2M: 2_000_000}

PREAMBLE_BYTES, ADDRESS_BYTES, CRC_BYTES, PCF_BITS = 1, 5, 2, 9
"""Enhanced ShockBurst framing as the Crazyradios configure it (5-byte address, 2-byte CRC, 9-bit packet control
field: nRF24LU1+ PS table 18; crazyradio2-firmware esb.c ``esb_init``: 4-byte base + prefix, 6-bit length + 3-bit
S1, 16-bit CRC)."""

ARD_ACK_BYTES = {DR_250K: (0, 0, 8, 16, 24, 32), DR_1M: (15, 32), DR_2M: (5, 32)}
"""The Crazyradio PA firmware's ARD choice when ARD is given as an ACK payload length (``radio.c`` ``ardStep``):
the first 250 us step whose entry covers the length."""


def time_on_air_s(payload_bytes: int, rate: int) -> float:
    """One ESB packet's time on air (nRF24LU1+ PS table 18, T_OA; the same for an acknowledgement, T_ACK)."""
    bits = 8 * (PREAMBLE_BYTES + ADDRESS_BYTES + payload_bytes + CRC_BYTES) + PCF_BITS
    return bits / RATE_BPS[rate]


def ard_s(ard: int, rate: int) -> float:
    """The auto-retransmit delay a Crazyradio PA uses for the SET_RADIO_ARD value ``ard``: bit 7 set means "an ACK
    payload of (ard & 0x7F) bytes" and picks the delay from `ARD_ACK_BYTES`; otherwise (ard & 0x0F + 1) x 250 us."""
    if ard & 0x80:
        nbytes = min(ard & 0x7F, 32)
        steps = ARD_ACK_BYTES[rate]
        step = next((i for i, covered in enumerate(steps) if covered >= nbytes), len(steps) - 1)
        return (step + 1) * 250e-6
    return ((ard & 0x0F) + 1) * 250e-6


@dataclass(frozen=True)
class RadioType:
    """One kind of Crazyradio: what its USB descriptors say, what its firmware accepts, and what each operation
    costs. `SOURCES` gives each timing figure's source."""

    name: str
    product: str
    manufacturer: str
    bcd_device: int
    """bcdDevice; cflib reads its version as ``float('%x.%x' % (bcd >> 8, bcd & 0xFF))``."""
    serial_digits: int
    interface_subclass: int
    endpoint_interval: int
    endpoints_in_first: bool
    max_channel: int
    """Highest channel the dongle transmits on (a higher one is ignored by the PA, never acknowledged by the 2.0)."""
    rates: tuple[int, ...]
    """Data rates it transmits at (the 2.0 accepts 250 kbps but never acknowledges a packet sent at it)."""
    default_channel: int
    control_s: float
    """One control transfer (a vendor request or a standard one), end to end."""
    bulk_out_s: float
    """The bulk OUT transfer of one packet (USB only; the radio starts when it is done)."""
    bulk_in_s: float
    """The bulk IN transfer of the answer once the radio is done (USB only)."""
    reset_s: float
    """A USB port reset (cflib resets the dongle on Linux when it opens it)."""
    ramp_s: float
    """Radio ramp-up before each transmission and before listening for its acknowledgement."""
    upload_s_per_byte: float
    """Loading the payload into the radio, per byte (T_UL)."""
    irq_s: dict[int, float] = field(default_factory=dict)
    """From the acknowledgement's end to the firmware seeing it (T_IRQ), per data rate."""
    ack_timeout_s: float | None = None
    """Wait after an unacknowledged transmission before the next attempt; None: the ARD set by SET_RADIO_ARD."""


CRAZYRADIO_PA = RadioType(
    name="crazyradio_pa",
    product="Crazyradio PA USB Dongle",
    manufacturer="Bitcraze",
    bcd_device=0x0053,
    serial_digits=10,
    interface_subclass=0xFF,
    endpoint_interval=6,
    endpoints_in_first=True,
    max_channel=125,
    rates=(DR_250K, DR_1M, DR_2M),
    default_channel=2,
    control_s=1.0e-3,
    bulk_out_s=0.2e-3,
    bulk_in_s=0.2e-3,
    reset_s=10e-3,
    ramp_s=130e-6,
    upload_s_per_byte=1e-6,
    irq_s={DR_250K: 8.2e-6, DR_1M: 8.2e-6, DR_2M: 6.0e-6},
    ack_timeout_s=None,
)

CRAZYRADIO_2 = RadioType(
    name="crazyradio_2",
    product="Crazyradio 2.0",
    manufacturer="Bitcraze AB",
    bcd_device=0x0504,
    serial_digits=16,
    interface_subclass=0x00,
    endpoint_interval=0,
    endpoints_in_first=True,
    max_channel=100,
    rates=(DR_1M, DR_2M),
    default_channel=42,
    control_s=2.5e-3,
    bulk_out_s=0.125e-3,
    bulk_in_s=0.125e-3,
    reset_s=10e-3,
    ramp_s=130e-6,
    upload_s_per_byte=0.0,
    irq_s={DR_250K: 8.2e-6, DR_1M: 8.2e-6, DR_2M: 6.0e-6},
    ack_timeout_s=500e-6,
)

RADIO_TYPES: dict[str, RadioType] = {t.name: t for t in (CRAZYRADIO_PA, CRAZYRADIO_2)}
"""The dongle types by the names missions use (``radio.dongle_type``)."""

SOURCES: dict[str, dict[str, str]] = {
    "crazyradio_pa": {
        "control_s": "about 1 ms: crazyradio-firmware usb_radio_protocol.md, 'Set radio channel'",
        "bulk_out_s": "estimate: chosen so that one link's smallest transaction (1-byte packet, 1-byte ack) "
        "takes about 1 ms, the ~1000 transactions/s of docs/radio.md 'Radio budget'",
        "bulk_in_s": "estimate, as bulk_out_s",
        "reset_s": "lower bound: USB 2.0 spec 7.1.7.5, reset signalling >= 10 ms (re-enumeration not counted)",
        "ramp_s": "nRF24LU1+ PS v1.0, Tstby2a = 130 us",
        "upload_s_per_byte": "nRF24LU1+ PS table 18 T_UL at the radio SPI's 8 MHz (radio.c radioInit, RFCTL)",
        "irq_s": "nRF24LU1+ PS table 18: 8.2 us at 1 Mbps, 6.0 us at 2 Mbps; 250 kbps: estimate (8.2 us)",
        "ack_timeout_s": "the ARD: radio.c radioUpdateRetr / nRF24LU1+ PS table 17 (500 us at 1-2 Mbps, "
        "1500 us at 250 kbps for cflib's 32-byte ARD)",
    },
    "crazyradio_2": {
        "control_s": "about 2.5 ms: github.com/bitcraze/crazyradio2-firmware/issues/9 (libusb_control_transfer timed)",
        "bulk_out_s": "estimate: with bulk_in_s and the radio time of a short packet, the ~0.7 ms of a bulk "
        "write and read in github.com/bitcraze/crazyradio2-firmware/issues/9",
        "bulk_in_s": "estimate, as bulk_out_s",
        "reset_s": "lower bound: USB 2.0 spec 7.1.7.5, reset signalling >= 10 ms (re-enumeration not counted)",
        "ramp_s": "estimate: the nRF24LU1+'s 130 us; crazyradio2-firmware esb.c keeps the nRF52840's default "
        "(nRF51-compatible) ramp-up",
        "upload_s_per_byte": "0: the nRF52840 radio reads the packet by EasyDMA",
        "irq_s": "estimate: the nRF24LU1+ figures",
        "ack_timeout_s": "500 us after each transmission's end: crazyradio2-firmware esb.c (timer CC1 = END + "
        "500); ARD is ignored (legacy_usb.c)",
    },
}


def radio_s(
    radio: RadioType, rate: int, up_bytes: int, ack_bytes: int, attempts: int, acked: bool, ard: float
) -> float:
    """Radio time of one bulk packet: ``attempts`` transmissions, the last one acknowledged with ``ack_bytes`` of
    payload if ``acked``. A lost attempt costs ramp-up, time on air and the wait for its acknowledgement (the ARD
    ``ard`` on a PA, the 2.0's timeout); an acknowledged one ramp-up, time on air, the turnaround and the
    acknowledgement (T_ESB without the upload, which is paid once)."""
    up_air = time_on_air_s(up_bytes, rate)
    wait = radio.ack_timeout_s if radio.ack_timeout_s is not None else ard
    lost = attempts - 1 if acked else attempts
    total = radio.upload_s_per_byte * up_bytes + lost * (radio.ramp_s + up_air + wait)
    if acked:
        total += 2 * radio.ramp_s + up_air + time_on_air_s(ack_bytes, rate) + radio.irq_s[rate]
    return total


def transaction_s(
    radio: RadioType, rate: int = DR_2M, up_bytes: int = 1, ack_bytes: int = 1, retries: int = 0, ard: float = 500e-6
) -> float:
    """One acknowledged packet end to end as cflib's ``Crazyradio.send_packet`` sees it: bulk write, radio, bulk
    read. The defaults are the smallest transaction (a null packet acknowledged by a one-byte empty ack)."""
    return radio.bulk_out_s + radio_s(radio, rate, up_bytes, ack_bytes, retries + 1, True, ard) + radio.bulk_in_s


def ceiling_per_s(radio: RadioType, switching: bool, rate: int = DR_2M) -> float:
    """The most transactions a second one dongle can carry: smallest packets back to back, each behind one setup
    call when ``switching`` (cflib's ``Crazyradio.set_address`` before every packet when the links of one dongle
    take turns)."""
    per = transaction_s(radio, rate) + (radio.control_s if switching else 0.0)
    return 1.0 / per
