#!/usr/bin/env python3
"""Writes a dense two-way crowd scenario (BENCHMARKS.md, "Admission"): N UAVs on a straight road
12 m wide, on a grid 1.2 m apart in two blocks 30 m apart, each block flying through the other to
the far side. Usage: scripts/crowd_scenario.py N > crowd.json"""

import json
import sys


def crowd(n: int) -> dict:
    width, rows, spacing = 12.0, 9, 1.2
    per_block = (n + 1) // 2
    cols = (per_block + rows - 1) // rows
    length = 2 * cols * spacing + 80.0
    segments = []
    step = 10.0
    x = 0.0
    while x < length:
        x1 = min(x + step, length)
        segments.append([[x1, -width / 2], [x, -width / 2], [x1, width / 2], [x, width / 2]])
        x = x1
    uavs = []
    for i in range(n):
        block, k = divmod(i, per_block)
        col, row = divmod(k, rows)
        y = -4.8 + row * spacing
        if block == 0:
            start = 5.0 + col * spacing
            goal = start + cols * spacing + 30.0
        else:
            start = length - 5.0 - col * spacing
            goal = start - cols * spacing - 30.0
        uavs.append({"id": f"u{i}", "start": [round(start, 3), round(y, 3)], "goal": [round(goal, 3), round(y, 3)]})
    return {"name": f"crowd{n}", "params": {"t_max": 120}, "segments": segments, "uavs": uavs}


if __name__ == "__main__":
    if len(sys.argv) != 2 or not sys.argv[1].isdigit() or int(sys.argv[1]) < 2:
        sys.exit("usage: scripts/crowd_scenario.py N  (N >= 2)")
    json.dump(crowd(int(sys.argv[1])), sys.stdout)
    sys.stdout.write("\n")
