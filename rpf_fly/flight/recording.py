"""The flight loop's recorder writing the MCAP flight log (docs/log-format.md).

Converts the loop's monotonic seconds to nanoseconds since the Unix epoch (one offset taken at the start), and
the loop's objects to the log's topics: poses and /tf at the mocap rate, planner steps and setpoints at the
planning rate, status at 10 Hz, events as they happen, the scene once; in a dry run also the simulated world's
truth (``/truth/<drone>``, every world step, fed by :class:`rpf_fly.flight.truth.TruthFeed`). With a ``sink`` (the
live view, :class:`rpf_fly.log.live.LiveView`), every message written is also handed to it by the log's writer
thread, the same bytes as the file's.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.events import FlightEvent
from rpf_fly.flight.poses import TrackedPose, stamp_us
from rpf_fly.flight.radio_load import RadioLoadFeed
from rpf_fly.flight.truth import TruthBatch, TruthFeed
from rpf_fly.log.encoding import planner_json
from rpf_fly.log.metadata import mission_metadata, obstacle_dict, scenario_metadata
from rpf_fly.log.writer import FlightLog, Out, Sink
from rpf_fly.mission.model import Mission
from rpf_fly.planning.obstacles import FAR
from rpf_fly.planning.planner import PlanStep
from rpf_fly.radio.backend import DroneState
from rpf_fly.radio.budget import radio_loads
from rpf_fly.radio.schedule import LinkCount, MeasuredLoad

TF_PERIOD_S = 0.05
"""/tf at 20 Hz: it repeats the mocap poses (logged at the full rate) for Foxglove's 3D panel, which needs no more."""

DRAIN_PERIOD_S = 0.05
"""The writer drains right after a planning tick at most this often (:meth:`McapRecorder.after_tick`)."""

POLL_FALLBACK_S = 0.25
"""The writer's own drain period in a flight: only a fallback when no tick asks (take-off, landing)."""


class McapRecorder:
    """Implements :class:`rpf_fly.flight.loop.Recorder` on a :class:`~rpf_fly.log.writer.FlightLog`.

    ``truth``: a dry run's truth source (:meth:`rpf_fly.flight.dry_run.DryRun.truth_samples`); its feed runs from
    here until :meth:`close`, so ``/truth`` covers the whole log and ends before the log does. None: no truth (a
    real flight has none).

    ``sink``: the log's sink (:class:`~rpf_fly.log.writer.FlightLog`), e.g. :meth:`rpf_fly.log.live.LiveView.publish`:
    it sees what the file holds, on the writer thread, so the loop's cost is unchanged.

    ``out``: no file; every message goes to ``out`` instead (a distributed flight's worker and coordinator publish
    them on Zenoh for the logger: rpf_fly/runtime/bus.py).

    ``mocap``: whether the frames' poses are logged (``/mocap/<drone>``); a distributed flight's worker leaves them
    to the flight's mocap relay (rpf_fly/runtime/relay.py) and logs its drones' ``/tf`` only.

    ``dynamics``: the model a dry run's simulated drones fly (the ``mission`` record's ``dynamics``; default the
    mission's ``dry_run.dynamics``)."""

    def __init__(
        self,
        path: str | Path,
        mission: Mission,
        seed: int = 0,
        source: str = "flight",
        truth: Callable[[], TruthBatch] | None = None,
        sink: Sink | None = None,
        radio: Callable[[], Mapping[str, LinkCount]] | None = None,
        radio_period_s: float | None = None,
        out: Out | None = None,
        radio_dongles: Iterable[int] | None = None,
        mocap: bool = True,
        dynamics: str | None = None,
    ):
        self.mission = mission
        self._mocap = mocap
        self._offset_ns = time.time_ns() - time.monotonic_ns()
        """Unix-epoch ns minus the loop's monotonic ns, an integer: logged (``mission.monotonic_offset_ns``) so that
        a replay gets the loop's own times back from the log, exactly for the tracker's stamps."""
        meta = mission_metadata(mission, seed, source=source, dynamics=dynamics)
        meta["monotonic_offset_ns"] = str(self._offset_ns)
        self.log = FlightLog(
            path, meta, scenario_metadata(mission), poll_interval_s=POLL_FALLBACK_S, sink=sink, out=out
        )
        self._last_drain_s = -math.inf
        self._sensing = mission.planner.sensing_range
        self._last_tf_s = -math.inf
        now = self._ns(time.monotonic())
        arena = {"x": list(mission.arena.x), "y": list(mission.arena.y), "z": list(mission.arena.z)}
        goals = {d.name: complex(*d.goal) for d in mission.drones}
        self.log.scene(now, [obstacle_dict(o) for o in mission.obstacles], goals, arena, mission.flight.height)
        self.truth_feed = TruthFeed(truth, self._truth).start() if truth is not None else None
        self._plan = {load.dongle: load for load in radio_loads(mission)}
        self.radio_feed = None
        if radio is not None:  # /radio/<dongle>: the measured load of each dongle (rpf_fly/flight/radio_load.py)
            dongles = self._plan if radio_dongles is None else set(radio_dongles)  # a worker: its own dongle's
            feed = RadioLoadFeed(
                radio, self._radio, dongles, **({} if radio_period_s is None else {"period_s": radio_period_s})
            )
            self.radio_feed = feed.start()

    @property
    def path(self) -> Path:
        return self.log.path

    def _ns(self, t_s: float) -> int:
        return round(t_s * 1e9) + self._offset_ns

    def poses(self, t_s: float, poses: dict[str, TrackedPose]) -> None:
        """One frame's fresh poses, stamped with the frame's receive time as the tracker holds it (the poses of
        one frame share it; ``t_s``, the loop's time at the call, only when there are none): the replay feeds
        them back to a tracker at exactly that time (stamps on the tracker's 1 us grid, so in integer ns)."""
        tf_due = bool(poses) and t_s - self._last_tf_s >= TF_PERIOD_S
        if not (self._mocap or tf_due):
            return
        stamp = next(iter(poses.values())).stamp_s if poses else None
        t = stamp_us(stamp) * 1000 + self._offset_ns if stamp is not None else self._ns(t_s)
        items = {name: (pose.position, pose.quaternion) for name, pose in poses.items()}
        if self._mocap:
            self.log.poses(t, items)
        if tf_due:
            self._last_tf_s = t_s
            self.log.tf(t, items)

    def planner_steps(
        self, t_s: float, tick: int, records: list[tuple[DroneAgent, TrackedPose | None, PlanStep | None, str]]
    ) -> None:
        """One tick's planner records. Only references cross to the writer thread (poses, goals and headings are
        immutable values, a step's fields numpy scalars); :meth:`_planner_message` builds the messages there."""
        steps = {
            agent.name: (
                tick,
                pose.position,
                agent.goal,
                agent.heading,
                step,
                mode,
                agent.planned_from if step is not None else None,
            )
            for agent, pose, step, mode in records
            if pose is not None
        }
        self.log.planner_steps(self._ns(t_s), steps, self._planner_message)

    def _planner_message(self, t_ns: int, value: tuple) -> bytes:
        """Writer thread: one ``rpf_fly.PlannerStep`` from what :meth:`planner_steps` handed over."""
        tick, position, goal, heading, step, mode, reference = value
        fields: dict = dict(
            tick=tick,
            position=position,
            goal=goal,
            heading=math.atan2(heading.imag, heading.real),
            goal_distance=abs(goal - complex(position[0], position[1])),
            mode=mode,
        )
        if reference is not None:
            fields["reference"] = reference
        if step is None:
            fields.update(eta=None, lam=None)
        else:
            d_o = float(step.obstacle_distance)
            fields.update(
                eta=float(step.eta),
                lam=float(step.lam),
                f_a=complex(step.f_a),
                f_r=complex(step.f_r),
                f_in=complex(step.f_in),
                direction=complex(step.direction),
                neighbours=int(step.neighbours),
                obstacle_distance=d_o if d_o < min(FAR, self._sensing + 1e-9) else None,
            )
        return planner_json(t_ns, fields)

    def _truth(self, stamp_s: float, states: dict[str, Any]) -> None:
        """The feed's thread: one world sample (``time.monotonic()`` seconds, shared with this process)."""
        self.log.truth(self._ns(stamp_s), states)

    def _radio(self, t_s: float, loads: list[MeasuredLoad]) -> None:
        """The radio feed's thread: one window of every dongle's measured load."""
        t = self._ns(t_s)
        for load in loads:
            plan = self._plan.get(load.dongle)
            self.log.radio(
                t,
                load.dongle,
                drones=load.drones or (plan.drones if plan else ()),
                window_s=load.window_s,
                packets=load.packets,
                transactions=load.transactions,
                planned_per_s=plan.needed if plan else 0.0,
                budget_per_s=plan.budget if plan else 0.0,
                setpoints_superseded=load.superseded,
            )

    def after_tick(self, t_s: float) -> None:
        """The loop finished a planning tick and waits for the next frame: let the writer drain now (its GIL-holding
        burst then falls in that idle gap instead of delaying the next frame's setpoints)."""
        if t_s - self._last_drain_s >= DRAIN_PERIOD_S:
            self._last_drain_s = t_s
            self.log.drain_soon()

    def setpoints(self, sent: list[tuple[str, tuple[float, float, float], float]]) -> None:
        """The setpoints handed to the radio this tick: ``(drone, position, send time)``."""
        ns = self._ns
        self.log.setpoints([(name, ns(t), position, 0.0) for name, position, t in sent])

    def status(self, t_s: float, agent: DroneAgent, state: DroneState | None) -> None:
        battery = state.battery.voltage_v if state is not None and state.battery is not None else None
        quality = state.link.quality_pct / 100.0 if state is not None and state.link.quality_pct is not None else None
        latency = state.link.latency_ms if state is not None else None
        outcome = agent.outcome.value if agent.outcome is not None and agent.phase.terminal else None
        self.log.status(
            agent.name,
            self._ns(t_s),
            state=agent.phase.value,
            battery_v=battery,
            link_quality=quality,
            latency_ms=latency,
            outcome=outcome,
            estimate=state.position_m if state is not None else None,
            target=state.target_m if state is not None else None,
        )

    def event(self, event: FlightEvent) -> None:
        self.log.event(
            self._ns(event.time_s), event.level, event.message, name=event.drone or "flight", file=event.kind
        )

    def close(self) -> None:
        if self.radio_feed is not None:
            self.radio_feed.stop()
        if self.truth_feed is not None:
            self.truth_feed.stop()
        self.log.close()
