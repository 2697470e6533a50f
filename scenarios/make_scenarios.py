#!/usr/bin/env python3
"""Writes the shipped scenarios (mitre-joint roads from a centre polyline, as roads::RoadLayout::from_centerline).

Run from the repository root: python3 scenarios/make_scenarios.py
"""
import json
import math
import os


def road(points, width):
    """Segments [p1, p2, p3, p4] along the polyline, p1/p2 on the right wall, p3/p4 on the left;
    `width` is one number or one per point."""
    widths = width if isinstance(width, list) else [width] * len(points)
    def left_normal(k):
        dx, dy = points[k + 1][0] - points[k][0], points[k + 1][1] - points[k][1]
        n = math.hypot(dx, dy)
        return (-dy / n, dx / n)

    offsets = []
    for k in range(len(points)):
        half = widths[k] / 2
        if 0 < k < len(points) - 1:
            a, b = left_normal(k - 1), left_normal(k)
            bis = (a[0] + b[0], a[1] + b[1])
            n = math.hypot(*bis)
            bis = (bis[0] / n, bis[1] / n)
            s = half / (bis[0] * b[0] + bis[1] * b[1])
            offsets.append((bis[0] * s, bis[1] * s))
        else:
            n = left_normal(min(k, len(points) - 2))
            offsets.append((n[0] * half, n[1] * half))
    r = [[round(p[0] - o[0], 6), round(p[1] - o[1], 6)] for p, o in zip(points, offsets)]
    l = [[round(p[0] + o[0], 6), round(p[1] + o[1], 6)] for p, o in zip(points, offsets)]
    return [[r[i + 1], r[i], l[i + 1], l[i]] for i in range(len(points) - 1)]


def write(name, params, segments, uavs, regions=None):
    doc = {"name": name, "params": params, "segments": segments}
    if regions:
        doc["regions"] = [{"name": n, "segments": [a, b]} for n, a, b in regions]
    doc["uavs"] = [{"id": i, "start": s, "goal": g} for i, s, g in uavs]
    path = os.path.join(os.path.dirname(__file__), name + ".json")
    with open(path, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")


# Lab scale (the paper flew three Crazyflies): an L-shaped road 1.4 m wide in a 6 m x 5 m room. The
# model-error allowances cover what `scripts/model-error` measured on flights of the real firmware
# (docs/safety.md §12; BENCHMARKS.md).
write("lab3", {"delta": 2.0, "r_s": 1.0, "t_max": 90, "eta_p": 0.07, "eta_v": 0.5},
      road([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0], [4.0, 2.0], [4.0, 4.0]], 1.4),
      [("cf1", [0.4, -0.3], [4.3, 2.4]), ("cf2", [0.4, 0.3], [3.7, 2.9]), ("cf3", [1.2, 0.0], [4.0, 3.6])])

# The paper's kind of run: a winding one-way road (10 segments, 3 m wide, bends of 37-90 degrees and
# a hairpin) with 10 UAVs starting in two rows at its entry and spreading over its far end.
snake = [[0, 0], [8, 0], [14, 3], [18, 9], [16, 15], [10, 17], [4, 15], [2, 21], [6, 27], [13, 28], [20, 27]]
starts = [[1.0 + 1.2 * (i // 2), -0.7 if i % 2 == 0 else 0.7] for i in range(10)]
goals = [[19.0, 26.4], [19.0, 27.8], [17.0, 26.6], [17.0, 28.0], [15.0, 26.8],
         [15.0, 28.2], [13.0, 27.0], [13.0, 28.4], [11.0, 27.0], [11.0, 28.4]]
write("snake10", {"t_max": 120},
      road([[float(x), float(y)] for x, y in snake], 3.0),
      [(f"u{i}", s, g) for i, (s, g) in enumerate(zip(starts, goals))])

# The embedded default of `airroads serve`: six UAVs on the snake road, from its entry to its far end.
write("demo", {"t_max": 120},
      road([[float(x), float(y)] for x, y in snake], 3.0),
      [(f"uav{i + 1}", s, g) for i, (s, g) in enumerate(zip(starts[:6], goals[:6]))])

# Head-on traffic through a single narrow section: a 5 m long, 0.9 m wide section between 4 m wide
# roads, 8 UAVs each way. Two UAVs fit side by side in it (D_s + D_c + D_s = 0.5 m < 0.9 m).
narrow = [[-14.0, 0.0], [-6.0, 0.0], [-2.5, 0.0], [2.5, 0.0], [6.0, 0.0], [14.0, 0.0]]
west = [[-13.0 + 1.2 * (i // 4), -1.2 + 0.8 * (i % 4)] for i in range(8)]
east = [[13.0 - 1.2 * (i // 4), -1.2 + 0.8 * (i % 4)] for i in range(8)]
write("narrow16", {"t_max": 120},
      road(narrow, [4.0, 4.0, 0.9, 0.9, 4.0, 4.0]),
      [(f"w{i}", s, [e[0] + 1.0, e[1]]) for i, (s, e) in enumerate(zip(west, east))]
      + [(f"e{i}", s, [w[0] - 1.0, w[1]]) for i, (s, w) in enumerate(zip(east, west))])

# Tight bends: a 9-segment road 2 m wide with turns of 100-120 degrees, 10 UAVs from one end to the
# other. Route targets beyond an inner vertex used to aim the nominal input straight at it.
bends = [[0, 0], [6, 0], [3, 5], [9, 6], [6, 11], [12, 12], [9, 17], [15, 18], [12, 23], [18, 24]]
starts = [[1.0 + 1.0 * (i // 2), -0.45 if i % 2 == 0 else 0.45] for i in range(5)]
goals = [[17.0 - 1.0 * (i // 2), 23.4 if i % 2 == 0 else 24.3] for i in range(5)]
write("bends10", {"t_max": 120},
      road([[float(x), float(y)] for x, y in bends], 2.0),
      [(f"u{i}", s, g) for i, (s, g) in enumerate(zip(starts, goals))]
      + [(f"v{i}", [g[0], g[1]], [s[0], s[1]]) for i, (s, g) in enumerate(zip(starts, goals))])

# Three regions for `serve --region` (docs/regions.md): a straight road 60 m long, 4 m
# wide, in regions a (segments 0-3), b (4-7) and c (8-11), with six UAVs flying each way through all.
three = []
for k in range(6):
    x, y = 3.0 + 3.0 * (k // 3), -1.0 + 2.0 * (k % 3) / 2
    three.append((f"east{k}", [x, y], [x + 50.0, y]))
    three.append((f"west{k}", [60.0 - x, -y], [10.0 - x, -y]))
write("regions3", {"t_max": 120},
      road([[5.0 * k, 0.0] for k in range(13)], 4.0), three,
      regions=[("a", 0, 3), ("b", 4, 7), ("c", 8, 11)])


def network_road(name, start, end, pieces, half=2.0):
    """A straight road of a network from `start` to `end` (the middles of its end edges), 2·half wide."""
    (ax, ay), (bx, by) = start, end
    length = math.hypot(bx - ax, by - ay)
    dx, dy = (bx - ax) / length, (by - ay) / length
    nx, ny = -dy, dx

    def at(i):
        return (bx, by) if i == pieces else (ax + dx * length * i / pieces, ay + dy * length * i / pieces)

    def side(q, s):
        return [round(q[0] + s * nx * half, 9), round(q[1] + s * ny * half, 9)]

    segments = [[side(at(i + 1), 1), side(at(i), 1), side(at(i + 1), -1), side(at(i), -1)] for i in range(pieces)]
    return {"name": name, "segments": segments}


def square_junction(name, cx, cy, half=2.0):
    return {"name": name, "polygon": [[cx - half, cy - half], [cx + half, cy - half],
                                      [cx + half, cy + half], [cx - half, cy + half]]}


def write_network(name, params, roads, junctions, uavs, regions=None):
    doc = {"name": name, "params": params, "roads": roads, "junctions": junctions}
    if regions:
        doc["regions"] = regions
    doc["uavs"] = [{"id": i, "start": s, "goal": g} for i, s, g in uavs]
    path = os.path.join(os.path.dirname(__file__), name + ".json")
    with open(path, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")


# A depot with branches (a road network, docs/scenarios.md): the depot junction with a west spoke and
# landing pads to the north, a trunk east to a fork, and three branches from the fork. Ten UAVs leave
# the west spoke for the branches; six come back from the branches to the pads.
outbound = []
for k in range(10):
    start = [-6.0 - 3.0 * (k // 2), -1.0 if k % 2 == 0 else 1.0]
    if k % 3 == 0:
        goal = [30.0, 20.0 - 1.5 * k]
    elif k % 3 == 1:
        goal = [30.8, -20.0 + 1.5 * k]
    else:
        goal = [50.0 - 1.5 * k, 0.8]
    outbound.append((f"out{k}", start, goal))
homebound = [(f"home{k}", list(s), [-1.0 if k % 2 else 1.0, 12.0 - 2.0 * k])
             for k, s in enumerate([(29.0, 18.0), (31.0, 16.0), (29.0, -18.0), (31.0, -16.0), (48.0, -1.0), (44.0, -1.0)])]
depot_roads = [network_road("trunk", (2, 0), (28, 0), 6),
               network_road("west-spoke", (-2, 0), (-22, 0), 5),
               network_road("pads", (0, 2), (0, 14), 3),
               network_road("branch-north", (30, 2), (30, 22), 5),
               network_road("branch-south", (30, -2), (30, -22), 5),
               network_road("branch-east", (32, 0), (52, 0), 5)]
depot_junctions = [square_junction("depot", 0, 0), square_junction("fork", 30, 0)]
write_network("depot", {"t_max": 120}, depot_roads, depot_junctions, outbound + homebound)

# The same depot in three regions (docs/regions.md): `west` (the depot, its spoke, the pads and the
# trunk's first half), `east` (the trunk's second half and the fork) and `branches`: the borders cut
# the trunk and separate the fork from its branches.
write_network("depot-regions", {"t_max": 120}, depot_roads, depot_junctions, outbound + homebound, [
    {"name": "west", "roads": [{"road": "west-spoke", "segments": [0, 4]}, {"road": "pads", "segments": [0, 2]},
                               {"road": "trunk", "segments": [0, 2]}], "junctions": ["depot"]},
    {"name": "east", "roads": [{"road": "trunk", "segments": [3, 5]}], "junctions": ["fork"]},
    {"name": "branches", "roads": [{"road": r, "segments": [0, 4]}
                                   for r in ["branch-north", "branch-south", "branch-east"]]},
])
