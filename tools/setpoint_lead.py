"""How far ahead of what mocap sees does a flight's setpoint lead its drone, in seconds of the drone's velocity?

    python tools/setpoint_lead.py LOG [LOG ...]

Read with the mcap library alone: for every streamed setpoint (``/<drone>/setpoint``) of a drone cruising (speed
over 0.3 m/s from its mocap track over the last 0.1 s, acceleration under 0.3 m/s^2), its lead over the newest mocap
pose (``/mocap/<drone>``) along the velocity, divided by the speed. That is the time a neighbour's planner must
predict a drone ahead by to plan against its setpoint (`DroneAgent.prediction`: the controller's steady lag plus
the radio's setpoint latency). Prints one line a log: the count, mean, median and 10th / 90th percentiles.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from mcap.reader import make_reader

CRUISE_M_S = 0.3
STEADY_M_S2 = 0.3
WINDOW_S = 0.1


def leads(log: str) -> np.ndarray:
    """Every cruising setpoint's lead time over the drone's mocap pose, in seconds."""
    mocap: dict[str, list[tuple[float, float, float]]] = {}
    setpoints: dict[str, list[tuple[float, float, float]]] = {}
    with open(log, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            topic = channel.topic
            if topic.startswith("/mocap/"):
                into, name = mocap, topic.split("/")[2]
            elif topic.endswith("/setpoint"):
                into, name = setpoints, topic.split("/")[1]
            else:
                continue
            p = json.loads(message.data)["pose"]["position"]
            into.setdefault(name, []).append((message.log_time / 1e9, p["x"], p["y"]))
    found = []
    for name, stream in setpoints.items():
        track = np.array(mocap.get(name, []))
        if len(track) < 30:
            continue
        times = track[:, 0]
        for t, x, y in stream:
            i = int(np.searchsorted(times, t)) - 1
            j = int(np.searchsorted(times, times[i] - WINDOW_S))
            k = int(np.searchsorted(times, times[i] - 2 * WINDOW_S))
            if i < 20 or not (times[i] > times[j] > times[k]):
                continue
            v = (track[i, 1:] - track[j, 1:]) / (times[i] - times[j])
            before = (track[j, 1:] - track[k, 1:]) / (times[j] - times[k])
            speed = float(np.linalg.norm(v))
            if speed < CRUISE_M_S or np.linalg.norm((v - before) / WINDOW_S) > STEADY_M_S2:
                continue
            found.append(float((np.array([x, y]) - track[i, 1:]) @ v) / speed**2)
    return np.array(found)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+")
    for log in parser.parse_args().logs:
        found = leads(log)
        if not len(found):
            print(f"{log}: no cruising setpoint")
            continue
        p10, p50, p90 = np.percentile(found, [10, 50, 90])
        print(
            f"{log}: {len(found)} setpoints, lead mean {found.mean():.3f} s, median {p50:.3f} s, "
            f"p10 {p10:.3f} s, p90 {p90:.3f} s"
        )


if __name__ == "__main__":
    main()
