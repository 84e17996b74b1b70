"""``rpf-fly radio probe``: one emulated dongle measured through cflib's own radio driver, as a lab measures a real one.
Every bound comes from the dongle's figures (`rpf_fly.emulator.crazyradio_timing`, docs/radio.md): what a dongle
carries is bounded above (a slow host only carries less), a round trip below (a slow host only makes it longer)."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from rpf_fly.cli import get_app
from rpf_fly.emulator import crazyradio
from rpf_fly.emulator.crazyradio_timing import RADIO_TYPES, ceiling_per_s, transaction_s

LINKS = 8
SECONDS = 1.5


def _probe(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(get_app(), ["radio", "probe", *args])
    return result.exit_code, result.stdout, result.stderr


def test_a_dry_run_probe_of_one_dongle_with_eight_links_stays_within_its_figures() -> None:
    code, out, err = _probe("--dry-run", "--links", str(LINKS), "--seconds", str(SECONDS), "--json")
    assert code == 0, err
    one, many = (json.loads(line) for line in out.splitlines())
    assert set(one) == {
        "dongle",
        "radio",
        "links",
        "transactions_per_s",
        "per_link_per_s",
        "setpoint_rtt_ms",
        "address_switch_ms",
        "loss",
    }
    assert (one["dongle"], one["radio"], one["links"], many["links"]) == (0, "crazyradio_pa", 1, LINKS)
    pa = RADIO_TYPES["crazyradio_pa"]
    # what the dongle carried: never more than its figures allow (a transaction counted at either edge of the window
    # may fall outside it: one a link)
    assert 0 < one["transactions_per_s"] <= ceiling_per_s(pa, switching=False) + 1 / SECONDS
    assert 0 < many["transactions_per_s"] <= ceiling_per_s(pa, switching=True) + LINKS / SECONDS
    assert len(many["per_link_per_s"]) == LINKS and all(r > 0 for r in many["per_link_per_s"])
    assert sum(many["per_link_per_s"]) == pytest.approx(many["transactions_per_s"])
    # a round trip: the echo rides on the link's next acknowledgement at the earliest, after every other link had
    # its turn, each turn one transaction and one address switch (SET_RADIO_ADDRESS, a control transfer)
    turn_1 = transaction_s(pa)
    turn_8 = LINKS * (transaction_s(pa) + pa.control_s)
    assert one["setpoint_rtt_ms"]["p50"] >= 1000 * 2 * turn_1
    assert many["setpoint_rtt_ms"]["p50"] >= 1000 * turn_8
    # so it grows with the links as the turn does: at least 8 times (the turns' ratio is 18.7 on the figures; the
    # host's own time a transaction, the same in both, brings it towards 8), half that asserted
    assert many["setpoint_rtt_ms"]["p50"] >= LINKS / 2 * one["setpoint_rtt_ms"]["p50"]
    assert many["setpoint_rtt_ms"]["p99"] >= many["setpoint_rtt_ms"]["p50"]
    assert one["address_switch_ms"] == 0.0
    assert 0.0 <= one["loss"] < 0.2 and 0.0 <= many["loss"] < 0.2  # the dry run's bursty loss: a few percent
    assert crazyradio.plugged() is None  # the probe unplugged its dongle


def test_the_text_report_gives_the_missions_budget_figure() -> None:
    code, out, err = _probe("--dry-run", "--links", "2", "--radio", "crazyradio_2", "--dongle", "1", "--seconds", "0.5")
    assert code == 0, err
    lines = out.splitlines()
    assert lines[0].startswith("dongle 1 (crazyradio_2), 1 link: ") and "setpoint round trip p50" in lines[0]
    assert lines[1].startswith("dongle 1 (crazyradio_2), 2 links: ") and "address switch" in lines[1]
    carried = float(lines[1].split(": ")[1].split(" transactions/s")[0])
    assert lines[2].startswith(f"radio.budget_packets_s: {carried:.0f} ")
    assert carried <= ceiling_per_s(RADIO_TYPES["crazyradio_2"], switching=True) + 2 / 0.5


@pytest.mark.parametrize(
    "args, message",
    [
        ((), "radio probe: --drones: expected the radio:// URIs of powered-on drones on one dongle"),
        (("--dry-run", "--drones", "radio://0/80/2M/E7E7E7E701"), "radio probe: --drones: a dry run probes simulated"),
        (
            ("--drones", "fake://0/80/2M/E7E7E7E701"),
            "radio probe: --drones: 'fake://0/80/2M/E7E7E7E701' is not a radio",
        ),
        (
            ("--drones", "radio://0/80/2M/E7E7E7E701,radio://1/80/2M/E7E7E7E702"),
            "radio probe: --drones: the URIs are on dongles 0, 1: probe one dongle at a time",
        ),
        (
            ("--drones", "radio://0/80/2M/E7E7E7E701", "--dongle", "2"),
            "radio probe: --dongle 2: the drones' URIs are on dongle 0",
        ),
        (
            ("--drones", "radio://0/80/2M/E7E7E7E701", "--links", "2"),
            "radio probe: --links 2: only 1 drone(s) given in --drones",
        ),
        (("--dry-run", "--links", "0"), "radio probe: --links 0: expected at least 1"),
        (("--dry-run", "--seconds", "0"), "radio probe: --seconds 0: expected a positive number of seconds"),
    ],
)
def test_what_cannot_be_probed_is_one_line_and_exit_2(args: tuple[str, ...], message: str) -> None:
    code, out, err = _probe(*args)
    assert code == 2 and out == ""
    assert err.startswith(message) and err.count("\n") == 1, err
