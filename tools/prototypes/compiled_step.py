"""Prototype, not part of the product: what a compiled one-drone plan step would cost beside the ONNX call.

    pip install numba==0.68.1      # not a dependency of rpf_fly: this script alone uses it
    python tools/prototypes/compiled_step.py

Why it exists: two lines, the one-drone RPF-3 step at most 1.5x the onnxruntime call alone and the flight's latency
at most 1.5x a floor that does not plan, are out of reach of the numpy planner in CPython (docs/performance.md,
*Lines not met*). Meeting them means compiling the planner, which is the project's
decision (a dependency, and the planning package rewritten as per-drone loops that serve training in batches too).
This measures what that would buy, so the decision is taken on a number.

A numba kernel doing, for one drone, at least the arithmetic of the numpy step: neighbour sort and the policy's
observation rows, a guidance-like visibility test of the goal and 8 candidate nodes against every inflated circle,
attraction, summed repulsion over circles / boxes / static neighbours, the inter-robot force with margin, range and
keep-right, the wall-following / soft rule, capture, yield and a brake check. Timed as the flight would call it
(arrays from the view) beside the real onnxruntime call of policies/rpf3.onnx on the real observation.
"""

import math
import statistics
import sys

import numpy as np
from numba import njit

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
from dataclasses import replace  # noqa: E402

from bench_planner import ROOT, load_mission, make_planner, midflight_views, scenario_from_mission  # noqa: E402
from bench_planner import timed as bench_timed  # noqa: E402

from rpf_fly.planning.observation import build_observation  # noqa: E402
from rpf_fly.planning.planner import guided_view, sense_obstacles  # noqa: E402


def timed(fn):  # type: ignore[no-untyped-def]
    """Median of 7 means over 300 calls (tools/bench_planner.py's rule)."""
    return bench_timed(fn, 300, 7)


@njit(cache=True, fastmath=False)
def step_kernel(
    p,
    g,
    h,
    npos,
    nvel,
    nmask,
    circles,
    boxes,
    nodes,
    cost,
    eta,
    lam,
    obs,
    r,
    margin,
    rho,
    rho_static,
    sensing,
    neighbour_range,
    keep_right,
    static_speed,
    capture_radius,
    wall_threshold,
):
    px, py = p.real, p.imag
    # --- guidance-like: is the goal visible? else the best visible node of the 8 candidates
    best = g
    best_key = 1e300
    targets = np.empty(nodes.shape[0] + 1, dtype=np.complex128)
    targets[0] = g
    targets[1:] = nodes
    for t in range(targets.shape[0]):
        q = targets[t]
        dx, dy = q.real - px, q.imag - py
        seg2 = dx * dx + dy * dy + 1e-12
        clear = True
        for k in range(circles.shape[0]):
            cx, cy, rad = circles[k, 0], circles[k, 1], circles[k, 2] + r + margin
            u = ((cx - px) * dx + (cy - py) * dy) / seg2
            u = min(max(u, 0.0), 1.0)
            ex, ey = px + u * dx - cx, py + u * dy - cy
            if ex * ex + ey * ey < rad * rad:
                clear = False
                break
        if clear:
            if t == 0:
                best = g
                break
            key = math.sqrt(seg2) + cost[t - 1]
            if key < best_key:
                best_key, best = key, q
    # --- attraction
    ax, ay = best.real - px, best.imag - py
    dg = math.hypot(ax, ay)
    ax, ay = ax / (dg + 1e-12), ay / (dg + 1e-12)
    # --- summed repulsion and the nearest wall
    fx = fy = 0.0
    wall = 1e9
    for k in range(circles.shape[0]):
        dx, dy = px - circles[k, 0], py - circles[k, 1]
        ln = math.hypot(dx, dy)
        d_raw = ln - circles[k, 2]
        nx, ny = dx / (ln + 1e-12), dy / (ln + 1e-12)
        if d_raw < wall:
            wall = d_raw
        d_raw -= margin
        if d_raw <= rho and d_raw <= sensing:
            d = max(d_raw, 1e-3)
            m = (1.0 / d - 1.0 / rho) / (d * d)
            fx += m * nx
            fy += m * ny
    for k in range(boxes.shape[0]):
        bx, by = px - boxes[k, 0], py - boxes[k, 1]
        qx, qy = abs(bx) - boxes[k, 2], abs(by) - boxes[k, 3]
        mx, my = max(qx, 0.0), max(qy, 0.0)
        out = math.hypot(mx, my)
        if out > 0.0:
            d_raw = out - margin
            if d_raw <= rho:
                d = max(d_raw, 1e-3)
                m = (1.0 / d - 1.0 / rho) / (d * d)
                fx += m * math.copysign(mx, bx) / out
                fy += m * math.copysign(my, by) / out
    # --- neighbours: statics as obstacles, the others the inter-robot force; the observation's sort
    kn = npos.shape[0]
    dist = np.empty(kn)
    ix = 0.0
    iy = 0.0
    count = 0
    for j in range(kn):
        dx, dy = npos[j].real - px, npos[j].imag - py
        dj = math.hypot(dx, dy)
        dist[j] = dj if nmask[j] else 1e9
        if not nmask[j] or dj >= sensing:
            continue
        if abs(nvel[j]) < static_speed:
            d_raw = dj - r - margin
            if d_raw <= rho_static:
                d = max(d_raw, 1e-3)
                m = (1.0 / d - 1.0 / rho_static) / (d * d)
                fx -= m * dx / (dj + 1e-12)
                fy -= m * dy / (dj + 1e-12)
            continue
        d = max(dj, 1e-3)
        c = 0.5 - lam / max(dj - margin, 1e-3)
        c += max(lam / neighbour_range - 0.5, 0.0)
        c = min(c, 0.0)
        ix += c / d * dx
        iy += c / d * dy
        count += 1
    cr, sr = math.cos(keep_right), math.sin(keep_right)
    ix, iy = ix * cr - iy * sr, ix * sr + iy * cr
    order = np.argsort(dist)
    rows = obs.shape[0]
    for j in range(rows):
        if j < kn and dist[order[j]] < 1e8:
            q = npos[order[j]]
            v = nvel[order[j]]
            obs[j, 0] = q.real - px
            obs[j, 1] = q.imag - py
            obs[j, 2] = v.real
            obs[j, 3] = v.imag
            obs[j, 4] = 1.0
        else:
            obs[j, :] = 0.0
    fx *= eta
    fy *= eta
    # --- heading: wall-following and the soft rule
    tx, ty = ax + fx + ix, ay + fy + iy
    tn = math.hypot(tx, ty)
    push = fx * ax + fy * ay
    fr = math.hypot(fx, fy)
    n1x, n1y = -fy / (fr + 1e-12), fx / (fr + 1e-12)
    strength = abs(n1x * ix + n1y * iy)
    refx, refy = (ix, iy) if strength >= wall_threshold else (h.real, h.imag)
    if n1x * refx + n1y * refy < -1e-9 * math.hypot(refx, refy):
        n1x, n1y = -n1x, -n1y
    mode = 0
    if push < -1.0:
        k = max((2 * r - wall) / r, 0.0)
        dx, dy = n1x + k * fx / (fr + 1e-12), n1y + k * fy / (fr + 1e-12)
        mode = 1
    elif push < 0.0:
        dx, dy = tx + 2 * fr * n1x, ty + 2 * fr * n1y
        mode = 2
    else:
        dx, dy = tx, ty
    ln = math.hypot(dx, dy)
    dx, dy = dx / (ln + 1e-12), dy / (ln + 1e-12)
    # --- capture, yield, brake
    dgoal = abs(g - p)
    if dgoal < capture_radius and dgoal < wall:
        sx, sy = (g.real - px) / (dgoal + 1e-12) + ix, (g.imag - py) / (dgoal + 1e-12) + iy
        ln = math.hypot(sx, sy)
        dx, dy, mode = sx / (ln + 1e-12), sy / (ln + 1e-12), 0
    y = 1.0 / (1.0 + math.hypot(ix, iy))
    y = max(y, 0.2)
    for j in range(kn):
        ox, oy = npos[j].real - px, npos[j].imag - py
        if nmask[j] and math.hypot(ox, oy) < 2 * r + margin + 0.1 and dx * ox + dy * oy > 0:
            y = 0.2
    return complex(dx * y, dy * y), mode, tn


for name in ("lab-3", "arena-a-6", "u-trap"):
    _, views = midflight_views(name)
    mission = load_mission(ROOT / "missions" / f"{name}.yaml")
    scenario = scenario_from_mission(mission, 0)
    settings = replace(
        mission.planner,
        kind="rpf3",
        policy=ROOT / "policies" / "rpf3.onnx",
        guidance=None,
        margin=None,
        capture_radius=None,
    )
    planner = make_planner(settings, scenario.obstacles, (scenario.arena_x, scenario.arena_y), scenario.goals)
    policy, cfg = planner.gains.policy, planner.config
    o = planner.obstacles
    circles = np.array([[c.real, c.imag, rr] for c, rr in zip(np.ravel(o.centers), np.ravel(o.radii))]).reshape(-1, 3)
    boxes = np.array(
        [
            [c.real, c.imag, hx, hy]
            for c, hx, hy in zip(np.ravel(o.box_center), np.ravel(o.box_half_x), np.ravel(o.box_half_y))
        ]
    ).reshape(-1, 4)
    nodes_all = planner.guidance.nodes if planner.guidance is not None else np.zeros(0, complex)
    nodes = np.ascontiguousarray(nodes_all[:8]) if nodes_all.shape[0] else np.zeros(8, complex)
    cost = np.linspace(1.0, 3.0, nodes.shape[0])
    steps, kernels, onnx = [], [], []
    for v in views:
        g, _, remaining = guided_view(v, planner.guidance, cfg.waypoint_reach)
        nearest = sense_obstacles(v, planner.obstacles, cfg)[0]
        observation = build_observation(g, nearest, cfg, policy.max_neighbours, remaining)
        obs = np.zeros((policy.max_neighbours, 5))
        mask = np.ascontiguousarray(v.neighbour_mask, dtype=np.bool_)
        npos = np.ascontiguousarray(v.neighbour_position)
        nvel = np.ascontiguousarray(v.neighbour_velocity)
        args = (complex(v.position), complex(v.goal), complex(v.heading), npos, nvel, mask, circles, boxes, nodes, cost)

        def kernel(a=args, obs=obs):
            return step_kernel(
                *a,
                0.05,
                2.0,
                obs,
                cfg.safety_radius,
                cfg.margin,
                0.2,
                0.5,
                cfg.sensing_range,
                0.8,
                math.radians(45.0),
                0.15,
                0.3,
                1.0,
            )

        def compiled_step(a=args, obs=obs, observation=observation):
            kernel(a, obs)
            return policy.act(observation)

        kernels.append(timed(kernel))
        onnx.append(timed(lambda: policy.act(observation)))
        steps.append(timed(compiled_step))
    print(
        f"{name:10s} kernel {statistics.median(kernels) * 1e6:5.1f} us, onnxruntime alone "
        f"{statistics.median(onnx) * 1e6:5.1f} us, kernel + onnxruntime {statistics.median(steps) * 1e6:5.1f} us: "
        f"{statistics.median(steps) / statistics.median(onnx):.2f}x; numpy step today "
        f"{statistics.median(timed(lambda v=v: planner.step(v)) for v in views) * 1e6:5.1f} us"
    )
