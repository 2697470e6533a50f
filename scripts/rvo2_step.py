"""RVO2/ORCA (its C++ core, through the `pyrvo` package) on an airroads scenario file.

Run by scripts/rvo2-bench inside its throw-away virtualenv; standard library only besides pyrvo.
For each scenario file (docs/scenarios.md; `airroads bench scale --write-scenarios DIR`
writes DIR/trunkN.json): one agent per UAV at its start, its preferred velocity pointing at its
goal at the fleet's top speed (zero within epsilon of the goal, and no faster than reaches the
goal in one step), agent radius D_c/2, time step dt, and the road's walls as obstacles: each
segment's barrier lines p2->p1 and p4->p3, the first segment's entry cap p2->p4 and the last
one's exit cap p1->p3, each as a two-vertex obstacle (a segment both sides of which block), then
processObstacles(). After the warm-up steps, each measured step times `doStep()` alone (the C++
core: k-d tree, neighbours, one 2-D LP per agent, integration); setting the preferred velocities
from Python is timed apart and left out. Prints one `RESULT` line per file for the driver:
`RESULT uavs p50_ms p99_ms us_per_agent pref_ms mean_speed min_dist`.
"""

import argparse
import importlib.metadata
import json
import math
import sys
import time

import pyrvo


def quantile(sorted_values, q):
    """Nearest-rank quantile, as `airroads bench scale` takes it."""
    if not sorted_values:
        return 0.0
    return sorted_values[round((len(sorted_values) - 1) * q)]


def walls(segments):
    """The road's walls as point pairs: the barrier lines of every segment plus both caps."""
    out = []
    for p1, p2, p3, p4 in segments:
        out.append((p2, p1))
        out.append((p4, p3))
    first, last = segments[0], segments[-1]
    out.append((first[1], first[3]))  # entry cap p2 -> p4
    out.append((last[0], last[2]))  # exit cap p1 -> p3
    return out


def min_distance(positions, cell):
    """Smallest centre distance between two agents (uniform grid of `cell` m; pairs beyond it
    are not looked at, so the answer is `cell` or more when no pair is closer)."""
    grid = {}
    for i, (x, y) in enumerate(positions):
        grid.setdefault((math.floor(x / cell), math.floor(y / cell)), []).append(i)
    best = float("inf")
    for (cx, cy), members in grid.items():
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                others = grid.get((cx + dx, cy + dy))
                if not others:
                    continue
                for i in members:
                    xi, yi = positions[i]
                    for j in others:
                        if j > i:
                            xj, yj = positions[j]
                            best = min(best, math.hypot(xi - xj, yi - yj))
    return best


def run(path, args):
    with open(path, encoding="utf-8") as f:
        scenario = json.load(f)
    params = scenario["params"]
    dt, d_c, eps = params["dt"], params["D_c"], params["epsilon"]
    radius = d_c / 2.0
    uavs = scenario["uavs"]
    n = len(uavs)

    sim = pyrvo.RVOSimulator()
    sim.set_time_step(dt)
    sim.set_agent_defaults(
        args.neighbor_dist,
        args.max_neighbors,
        args.time_horizon,
        args.time_horizon_obst,
        radius,
        args.max_speed,
    )
    for u in uavs:
        sim.add_agent(tuple(u["start"]))
    road_walls = walls(scenario["segments"])
    for a, b in road_walls:
        sim.add_obstacle([tuple(a), tuple(b)])
    sim.process_obstacles()
    goals = [tuple(u["goal"]) for u in uavs]
    if sim.get_num_agents() != n:
        sys.exit(f"error: {path}: RVO2 holds {sim.get_num_agents()} agents, the file {n} UAVs")

    vmax, reach = args.max_speed, args.max_speed * dt

    def set_preferred():
        for i, (gx, gy) in enumerate(goals):
            p = sim.get_agent_position(i)
            dx, dy = gx - p.x, gy - p.y
            dist = math.hypot(dx, dy)
            if dist <= eps:
                sim.set_agent_pref_velocity(i, (0.0, 0.0))
            else:
                speed = vmax if dist > reach else dist / dt
                sim.set_agent_pref_velocity(i, (dx / dist * speed, dy / dist * speed))

    for _ in range(args.warmup):
        set_preferred()
        sim.do_step()
    step_ms, pref_ms = [], []
    for _ in range(args.steps):
        started = time.perf_counter()
        set_preferred()
        stepped = time.perf_counter()
        sim.do_step()
        done = time.perf_counter()
        pref_ms.append((stepped - started) * 1e3)
        step_ms.append((done - stepped) * 1e3)

    velocities = [sim.get_agent_velocity(i) for i in range(n)]
    mean_speed = sum(math.hypot(v.x, v.y) for v in velocities) / n
    positions = [(p.x, p.y) for p in (sim.get_agent_position(i) for i in range(n))]
    closest = min_distance(positions, max(1.0, 4 * d_c))
    step_ms.sort()
    p50, p99 = quantile(step_ms, 0.5), quantile(step_ms, 0.99)
    mean_ms = sum(step_ms) / len(step_ms)
    pref = sum(pref_ms) / len(pref_ms)
    print(
        f"RVO2 {scenario.get('name', path)}: {n} agents, {len(road_walls)} walls, {args.steps} steps "
        f"after {args.warmup} warm-up: step p50 {p50:.2f} ms, p99 {p99:.2f} ms, "
        f"{mean_ms * 1e3 / n:.2f} µs per agent (mean); setting preferred velocities from Python "
        f"{pref:.1f} ms per step, not counted; mean speed after the last step {mean_speed:.2f} m/s, "
        f"closest pair {closest:.3f} m (D_c {d_c})",
        flush=True,
    )
    print(
        f"RESULT {n} {p50:.3f} {p99:.3f} {mean_ms * 1e3 / n:.3f} {pref:.3f} {mean_speed:.3f} {closest:.4f}",
        flush=True,
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="+", help="scenario files (trunkN.json)")
    parser.add_argument("--steps", type=int, default=40, help="measured steps per file")
    parser.add_argument("--warmup", type=int, default=2, help="steps before measuring")
    parser.add_argument("--max-speed", type=float, default=3.0, help="m/s: airroads' top speed")
    parser.add_argument("--neighbor-dist", type=float, default=5.0, help="m: airroads' r_s")
    parser.add_argument("--max-neighbors", type=int, default=10)
    parser.add_argument("--time-horizon", type=float, default=2.0, help="s, agents")
    parser.add_argument("--time-horizon-obst", type=float, default=1.0, help="s, walls")
    args = parser.parse_args()
    if args.steps < 1 or args.warmup < 0:
        parser.error("--steps must be at least 1 and --warmup at least 0")
    print(
        f"RVO2 (pyrvo {importlib.metadata.version('pyrvo')}) parameters: neighborDist {args.neighbor_dist} m, "
        f"maxNeighbors {args.max_neighbors}, timeHorizon {args.time_horizon} s, "
        f"timeHorizonObst {args.time_horizon_obst} s, maxSpeed {args.max_speed} m/s, "
        "radius D_c/2, timeStep dt (from each file)",
        flush=True,
    )
    for path in args.scenarios:
        run(path, args)


if __name__ == "__main__":
    main()
