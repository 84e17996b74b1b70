"""Write docs/foxglove-layout.json: the Foxglove layout for a flight, live (``rpf-fly fly --foxglove``) or from its log.

    python tools/make_foxglove_layout.py [--drones 10] [--out docs/foxglove-layout.json]

The file is in the format the Foxglove app exports and imports ("Layouts" menu, "Import from file..."): panel
configurations by id (``configById``, ids ``Type!name``), the panel tree (``layout``: splits with ``first``,
``second``, ``direction``, ``splitPercentage``), global variables, user scripts (``userNodes``) and playback settings.
Panels:

- a 3D panel in the ``world`` frame: the drones as the ``/tf`` frames (``world`` -> each drone, labelled), each
  drone's setpoint (``/<drone>/setpoint``) as an arrow in the drone's colour, and ``/scene`` (obstacles, goals,
  arena);
- a plot of the separation: the smallest planar distance between any two drones, computed from ``/tf`` by a user
  script saved in the layout (``/studio_script/separation``), against 2r for the default safety radius;
- a plot of altitude: each drone's ``/mocap/<drone>`` z;
- the event log (``/events``, ``foxglove.Log``).

Topic names are written out for drones ``cf1`` .. ``cfN`` (the names formations generate and the missions use); a
plot or setting for a drone that is not there stays empty. tests/log/test_foxglove_layout.py checks the shipped file
is what this script writes and that every topic it names is one the log writes.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rpf_fly.mission.model import PlannerSettings

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "docs" / "foxglove-layout.json"
SEPARATION_TOPIC = "/studio_script/separation"

COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")

SEPARATION_SCRIPT = """\
// rpf_fly: the smallest distance between any two drones, from /tf (world -> each drone), as rpf-fly review and the
// supervisor measure it: planar (x, y); also in 3D. Plotted against 2r. Written by tools/make_foxglove_layout.py.
type Vector3 = { x: number; y: number; z: number };
type FrameTransform = { child_frame_id: string; translation: Vector3 };
type TfEvent = { message: { transforms: FrameTransform[] } };

type Output = {
  min_planar_m: number;
  min_3d_m: number;
  closest_pair: string;
  drones: number;
};

export const inputs = ["/tf"];
export const output = "@OUTPUT@";

export default function script(event: TfEvent): Output | undefined {
  const frames = event.message.transforms;
  if (frames.length < 2) {
    return undefined;
  }
  let planar = Infinity;
  let spatial = Infinity;
  let pair = "";
  frames.forEach((a, i) => {
    frames.slice(i + 1).forEach((b) => {
      const dx = a.translation.x - b.translation.x;
      const dy = a.translation.y - b.translation.y;
      const dz = a.translation.z - b.translation.z;
      const d = Math.sqrt(dx * dx + dy * dy);
      if (d < planar) {
        planar = d;
        pair = a.child_frame_id + "-" + b.child_frame_id;
      }
      spatial = Math.min(spatial, Math.sqrt(dx * dx + dy * dy + dz * dz));
    });
  });
  return { min_planar_m: planar, min_3d_m: spatial, closest_pair: pair, drones: frames.length };
}
""".replace("@OUTPUT@", SEPARATION_TOPIC)


def drones(n: int) -> list[str]:
    return [f"cf{i}" for i in range(1, n + 1)]


def three_d(n: int) -> dict:
    """The 3D panel: world frame, a view from above and aside, the grid on the floor, the topics to draw."""
    topics: dict = {"/scene": {"visible": True}}
    for i, name in enumerate(drones(n)):
        topics[f"/{name}/setpoint"] = {
            "visible": True,
            "type": "arrow",
            "arrowScale": [0.15, 0.03, 0.03],
            "color": COLOURS[i % len(COLOURS)],
        }
    return {
        "cameraState": {
            "distance": 11.0,
            "perspective": True,
            "phi": 50.0,
            "thetaOffset": 30.0,
            "target": [0, 0, 0],
            "targetOffset": [0, 0, 0],
            "targetOrientation": [0, 0, 0, 1],
            "fovy": 45,
            "near": 0.05,
            "far": 500,
        },
        "followMode": "follow-none",
        "followTf": "world",
        "scene": {
            "transforms": {"showLabel": True, "labelSize": 0.15, "axisScale": 0.25, "lineWidth": 1},
            "labelScaleFactor": 1,
        },
        "transforms": {"frame:world": {"visible": True}},
        "topics": topics,
        "layers": {
            "grid": {
                "visible": True,
                "frameLocked": True,
                "label": "Grid (1 m)",
                "instanceId": "grid",
                "layerId": "foxglove.Grid",
                "frameId": "world",
                "size": 10,
                "divisions": 10,
                "lineWidth": 1,
                "color": "#248eff80",
                "position": [0, 0, 0],
                "rotation": [0, 0, 0],
                "order": 1,
            }
        },
        "publish": {
            "type": "point",
            "poseTopic": "/move_base_simple/goal",
            "pointTopic": "/clicked_point",
            "poseEstimateTopic": "/initialpose",
            "poseEstimateXDeviation": 0.5,
            "poseEstimateYDeviation": 0.5,
            "poseEstimateThetaDeviation": 0.26179939,
        },
        "imageMode": {},
    }


def plot(title: str, paths: list[dict]) -> dict:
    return {
        "title": title,
        "paths": paths,
        "showLegend": True,
        "legendDisplay": "floating",
        "showXAxisLabels": True,
        "showYAxisLabels": True,
        "isSynced": True,
        "xAxisVal": "timestamp",
        "sidebarDimension": 240,
    }


def separation_plot() -> dict:
    two_r = 2 * PlannerSettings().safety_radius
    return plot(
        "separation [m] (smallest planar distance between two drones)",
        [
            {
                "value": f"{SEPARATION_TOPIC}.min_planar_m",
                "enabled": True,
                "timestampMethod": "receiveTime",
                "label": "min distance",
                "color": "#1f77b4",
            },
            {
                "value": f"{two_r:g}",
                "enabled": True,
                "timestampMethod": "receiveTime",
                "label": f"2r = {two_r:g} m (the default planner.safety_radius)",
                "color": "#d62728",
            },
        ],
    )


def altitude_plot(n: int) -> dict:
    return plot(
        "altitude [m] (mocap z)",
        [
            {
                "value": f"/mocap/{name}.pose.position.z",
                "enabled": True,
                "timestampMethod": "receiveTime",
                "label": name,
                "color": COLOURS[i % len(COLOURS)],
            }
            for i, name in enumerate(drones(n))
        ],
    )


def layout(n: int = 10) -> dict:
    """The layout as a dict (the app's export format)."""
    return {
        "configById": {
            "3D!rpf-scene": three_d(n),
            "Plot!rpf-separation": separation_plot(),
            "Plot!rpf-altitude": altitude_plot(n),
            "RosOut!rpf-events": {"topicToRender": "/events", "searchTerms": [], "minLogLevel": 1},
        },
        "globalVariables": {},
        "userNodes": {"rpf-separation": {"name": "rpf separation", "sourceCode": SEPARATION_SCRIPT}},
        "playbackConfig": {"speed": 1},
        "layout": {
            "first": "3D!rpf-scene",
            "second": {
                "first": "Plot!rpf-separation",
                "second": {
                    "first": "Plot!rpf-altitude",
                    "second": "RosOut!rpf-events",
                    "direction": "column",
                    "splitPercentage": 50,
                },
                "direction": "column",
                "splitPercentage": 33,
            },
            "direction": "row",
            "splitPercentage": 58,
        },
    }


def text(n: int = 10) -> str:
    return json.dumps(layout(n), indent=2) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--drones", type=int, default=10)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    args.out.write_text(text(args.drones))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
