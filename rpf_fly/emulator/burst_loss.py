"""Bursty radio loss of a simulated drone's link: the two-state (Gilbert-Elliott) model with its figures
(:class:`BurstLoss`) and one link's state sequence on the world clock (:class:`BurstChannel`). A drone's
``LinkFaults.burst`` (rpf_fly/emulator/fake_world.py) turns it on; docs/radio.md, "Bursty loss".
"""

from __future__ import annotations

import bisect
import random
import threading
from dataclasses import dataclass


@dataclass(frozen=True)
class BurstLoss:
    """Bursty radio loss of one link: a two-state (Gilbert-Elliott) channel in continuous time.

    Why: a 2.4 GHz link loses packets in bursts (a WiFi burst on the channel, a body or the drone's own frame in the
    line of sight, a multipath fade, motor noise), not independently; a burst of tens of milliseconds costs a
    streamed setpoint or a few extpos in a row, which independent loss of the same mean rarely does. The link is in
    a *good* or a *bad* state; each state lasts an exponentially distributed time of mean `mean_good_s` /
    `mean_bad_s` (world time, whatever the traffic), and each radio attempt is lost with that state's probability.
    The defaults are a Crazyradio PA in a lab on a channel clear of the lab's WiFi (docs/radio.md, "Bursty loss",
    gives each figure's source or says it is an assumption):

    - long-run share of time in the bad state ``mean_bad_s / (mean_good_s + mean_bad_s)`` = 2.9 %;
    - long-run loss of an attempt at an arbitrary moment ``0.971 * 1 % + 0.029 * 60 %`` = 2.7 % (`mean_loss`);
      of all attempts, retries included (which crowd into the bursts), 4.6 % (`retried_loss`);
    - cflib's link quality (10 points a retry, averaged over the last 100 acks) reads 99.9 % in the good state and
      dips by about 1 point in a 30 ms burst, by 3 in a 100 ms one: below 100 %, never near the supervisor's 95 %.
    """

    good_loss: float = 0.01
    """Attempt loss in the good state (assumption: a line-of-sight Crazyradio PA link at lab range, 1 %)."""
    bad_loss: float = 0.6
    """Attempt loss in the bad state (assumption: most attempts collide with a WiFi frame burst or sit in a fade).
    A transaction then loses all its 4 attempts with 0.6^4 = 13 %: a burst costs retries and lost acks, while the
    100 lost acks in a row that drop cflib's link need a burst of near 100 % loss lasting over 0.1 s."""
    mean_good_s: float = 1.0
    """Mean time between bursts, seconds (assumption: about one burst a second)."""
    mean_bad_s: float = 0.03
    """Mean burst length, seconds (tens of ms: a WiFi TXOP burst or block-ack exchange lasts 2-10 ms and comes in
    trains; a fade at walking or flying speed lasts about half a wavelength, 6 cm, over 1 m/s: 60 ms)."""

    def __post_init__(self) -> None:
        for name in ("good_loss", "bad_loss"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], not {value}")
        for name in ("mean_good_s", "mean_bad_s"):
            value = getattr(self, name)
            if not value > 0.0:
                raise ValueError(f"{name} must be > 0 s, not {value}")

    @property
    def bad_share(self) -> float:
        """Long-run share of time in the bad state."""
        return self.mean_bad_s / (self.mean_good_s + self.mean_bad_s)

    @property
    def mean_loss(self) -> float:
        """Long-run probability that an attempt made at an arbitrary moment is lost (a transaction's first
        attempt): the time average of the two states' losses."""
        return (1.0 - self.bad_share) * self.good_loss + self.bad_share * self.bad_loss

    def retried_loss(self, arc_retries: int) -> float:
        """Long-run share of all attempts lost, retries included, for transactions at arbitrary moments that retry
        up to ``arc_retries`` times: higher than `mean_loss`, because the retries crowd into the bursts (a
        transaction makes 1.01 attempts in the good state, 2.18 in the bad one with the defaults)."""
        lost = made = 0.0
        for share, p in ((1.0 - self.bad_share, self.good_loss), (self.bad_share, self.bad_loss)):
            tries = sum(p**n for n in range(arc_retries + 1))  # attempt n+1 is made if the first n were lost
            made += share * tries
            lost += share * (tries - (1.0 - p ** (arc_retries + 1)))
        return lost / made


class BurstChannel:
    """The state sequence of one link's `BurstLoss` channel on the world clock, drawn lazily from its own seeded
    generator, so the bursts of a world seed and drone are the same in every run whatever the radio traffic (which
    attempts fall into them depends on the traffic). Thread-safe (the fake links of a world in this process call
    it from their own threads)."""

    KEEP_S = 600.0
    """Seconds of past states kept (about 1200 with the defaults): a late caller (a link thread whose clock reading
    is a little older) finds its state, and a test or tool looks a whole flight's bursts up afterwards."""

    def __init__(self, model: BurstLoss, seed: int | str) -> None:
        self.model = model
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        bad = self._rng.random() < model.bad_share  # the stationary distribution: world time 0 is any moment
        self._starts: list[float] = [0.0]
        self._bad: list[bool] = [bad]
        self._end = self._dwell(bad)

    def _dwell(self, bad: bool) -> float:
        return self._rng.expovariate(1.0 / (self.model.mean_bad_s if bad else self.model.mean_good_s))

    def _extend(self, t: float) -> None:
        while self._end <= t:
            bad = not self._bad[-1]
            self._starts.append(self._end)
            self._bad.append(bad)
            self._end += self._dwell(bad)
        if len(self._starts) > 64 and self._starts[32] < t - self.KEEP_S:
            del self._starts[:32], self._bad[:32]

    def bad_at(self, t: float) -> bool:
        """True while the link is in its bad state at world time ``t`` (seconds)."""
        with self._lock:
            self._extend(t)
            return self._bad[max(0, bisect.bisect_right(self._starts, t) - 1)]

    def loss_at(self, t: float) -> float:
        """The probability that an attempt at world time ``t`` is lost."""
        return self.model.bad_loss if self.bad_at(t) else self.model.good_loss

    def bad_intervals(self, start_s: float, end_s: float) -> list[tuple[float, float]]:
        """The bad states overlapping [start_s, end_s] as (start, end) world times, clipped to the window (only the
        last `KEEP_S` seconds are kept)."""
        with self._lock:
            self._extend(end_s)
            out = []
            bounds = self._starts[1:] + [self._end]
            for begin, end, bad in zip(self._starts, bounds, self._bad):
                if bad and end > start_s and begin < end_s:
                    out.append((max(begin, start_s), min(end, end_s)))
            return out
