#!/usr/bin/env python3
"""A small reader of airroads' binary stream (`GET /ws?format=bin`, format version 1; docs/streams.md,
Binary stream), with nothing but the Python standard library.

    python3 scripts/airroads_stream.py ws://127.0.0.1:8080/ws?format=bin [--frames 20]
    python3 scripts/airroads_stream.py --check http://127.0.0.1:8080

Without --check it prints one line per message with its size in bytes (also for the JSON stream,
`/ws` without format=bin). --check connects to a running server, reads a
roster and 20 tick frames (whole fleet, then a viewport) and checks them against `GET /api/state`;
it exits 1 with the reason on the first mismatch (CI runs it, see scripts/stream-check).

Use from Python: `for frame in Stream(url): ...` yields decoded frames (`decode`).
"""

import base64
import json
import math
import os
import socket
import struct
import sys
import urllib.parse
import urllib.request

VERSION = 1
KIND_TICK, KIND_ROSTER, KIND_RESERVATIONS, KIND_REGION = 1, 2, 3, 4
REGION_HEADER = struct.Struct("<BBHIQdf")  # 28 bytes
REGION_RECORD = struct.Struct("<8fBBH")  # 36 bytes after the id
TICK_HEADER = struct.Struct("<BBHIQdIIIffff")  # 52 bytes
RECORD = struct.Struct("<I8fBBH")  # 40 bytes
STATUSES = ["flying", "arrived", "braking", "failed", "stale", "lost", "connecting", "taking_off",
            "landing", "landed", "stopped", "stopping", "waiting"]
FLAG_PAUSED, FLAG_FILTERED = 1, 2
UAV_ARRIVED, UAV_LOST, UAV_GHOST = 1, 2, 4


def decode_region(message):
    """A region frame (kind 4, `serve --region`: another region's state message) as
    {"kind": "region", "region", "tick", "time", "age_at_send_s", "uavs": [{"id", "p", "v", "u",
    "target", "status", "arrived", "lost", "ghost", "unheard_ms"}]}."""
    _, _, name_length, count, tick, time, age = REGION_HEADER.unpack_from(message, 0)
    at = REGION_HEADER.size + name_length
    region = message[REGION_HEADER.size:at].decode("utf-8")
    uavs = []
    for _ in range(count):
        (id_length,) = struct.unpack_from("<H", message, at)
        uav_id = message[at + 2:at + 2 + id_length].decode("utf-8")
        at += 2 + id_length
        px, py, vx, vy, ux, uy, tx, ty, status, flags, unheard = REGION_RECORD.unpack_from(message, at)
        at += REGION_RECORD.size
        uavs.append({"id": uav_id, "p": [px, py], "v": [vx, vy], "u": [ux, uy], "target": [tx, ty],
                     "status": STATUSES[status] if status < len(STATUSES) else "flying",
                     "arrived": bool(flags & UAV_ARRIVED), "lost": bool(flags & UAV_LOST),
                     "ghost": bool(flags & UAV_GHOST), "unheard_ms": unheard})
    if at != len(message):
        raise ValueError(f"{len(message) - at} bytes after the last record")
    return {"kind": "region", "region": region, "tick": tick, "time": time, "age_at_send_s": age,
            "uavs": uavs}


def decode(message):
    """One binary message as a dict: {"kind": "roster", "roster_version", "uavs"},
    {"kind": "reservations", "version", "reservations"}, a region frame (`decode_region`) or
    {"kind": "tick", "roster_version", "tick", "time", "paused", "filtered", "fleet", "road_version",
    "min_collision_margin_m", "min_road_margin_m", "d_c", "d_s", "uavs": [{"index", "p", "v", "u",
    "target", "status", "arrived", "lost"}]} (margins None when NaN)."""
    if len(message) < 2 or message[0] != VERSION:
        raise ValueError(f"not a version {VERSION} frame")
    if message[1] == KIND_ROSTER:
        (roster_version,) = struct.unpack_from("<I", message, 4)
        body = json.loads(message[8:].decode("utf-8"))
        return {"kind": "roster", "roster_version": roster_version, "uavs": body["uavs"]}
    if message[1] == KIND_RESERVATIONS:
        (version,) = struct.unpack_from("<I", message, 4)
        body = json.loads(message[8:].decode("utf-8"))
        return {"kind": "reservations", "version": version, "reservations": body["reservations"]}
    if message[1] == KIND_REGION:
        return decode_region(message)
    if message[1] != KIND_TICK:
        raise ValueError(f"unknown frame kind {message[1]}")
    (_, _, flags, roster_version, tick, time, fleet, count, road_version,
     min_collision, min_road, d_c, d_s) = TICK_HEADER.unpack_from(message, 0)
    if len(message) != TICK_HEADER.size + count * RECORD.size:
        raise ValueError(f"{len(message)} bytes for {count} records")
    uavs = []
    for k in range(count):
        index, px, py, vx, vy, ux, uy, tx, ty, status, uflags, _ = RECORD.unpack_from(
            message, TICK_HEADER.size + k * RECORD.size)
        uavs.append({"index": index, "p": [px, py], "v": [vx, vy], "u": [ux, uy], "target": [tx, ty],
                     "status": STATUSES[status], "arrived": bool(uflags & UAV_ARRIVED),
                     "lost": bool(uflags & UAV_LOST)})
    nan_none = lambda x: None if math.isnan(x) else x  # noqa: E731
    return {"kind": "tick", "roster_version": roster_version, "tick": tick, "time": time,
            "paused": bool(flags & FLAG_PAUSED), "filtered": bool(flags & FLAG_FILTERED),
            "fleet": fleet, "road_version": road_version,
            "min_collision_margin_m": nan_none(min_collision), "min_road_margin_m": nan_none(min_road),
            "d_c": d_c, "d_s": d_s, "uavs": uavs}


class Stream:
    """A WebSocket client (RFC 6455, client side, no extensions) yielding decoded frames."""

    def __init__(self, url, timeout=10.0):
        parts = urllib.parse.urlsplit(url)
        if parts.scheme != "ws":
            raise ValueError("expected a ws:// URL")
        self.sock = socket.create_connection((parts.hostname, parts.port or 80), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        target = parts.path + (f"?{parts.query}" if parts.query else "")
        self.sock.sendall((f"GET {target} HTTP/1.1\r\nHost: {parts.netloc}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                           "Sec-WebSocket-Version: 13\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("closed during the handshake")
            head += chunk
        head, self.buffer = head.split(b"\r\n\r\n", 1)
        status = head.split(b"\r\n", 1)[0]
        if b" 101 " not in status + b" ":
            raise ConnectionError(f"refused: {status.decode(errors='replace')} {self.buffer[:300]!r}")

    def _read(self, n):
        while len(self.buffer) < n:
            chunk = self.sock.recv(1 << 16)
            if not chunk:
                raise ConnectionError("the stream closed")
            self.buffer += chunk
        out, self.buffer = self.buffer[:n], self.buffer[n:]
        return out

    def _send(self, opcode, payload=b""):
        mask = os.urandom(4)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(bytes([0x80 | opcode, 0x80 | len(payload)]) + mask + masked)

    def message(self):
        """The next text (str) or binary (bytes) message; answers pings on the way."""
        data, first = b"", None
        while True:
            b0, b1 = self._read(2)
            opcode, length = b0 & 0x0F, b1 & 0x7F
            if length == 126:
                (length,) = struct.unpack(">H", self._read(2))
            elif length == 127:
                (length,) = struct.unpack(">Q", self._read(8))
            payload = self._read(length)
            if opcode == 9:
                self._send(10, payload[:125])
            elif opcode == 8:
                raise ConnectionError("the server closed the stream")
            elif opcode in (0, 1, 2):
                first = first if opcode == 0 else opcode
                data += payload
                if b0 & 0x80:
                    return data.decode() if first == 1 else data

    def __iter__(self):
        while True:
            yield decode(self.message())

    def close(self):
        try:
            self._send(8)
        finally:
            self.sock.close()


def check(http):
    """Reads the stream of the server at `http` and checks it against GET /api/state."""
    ws = http.replace("http://", "ws://", 1).rstrip("/") + "/ws?format=bin"
    stream = Stream(ws)
    frames = iter(stream)
    roster = next(frames)
    assert roster["kind"] == "roster", f"the first frame is a {roster['kind']} frame"
    state = json.load(urllib.request.urlopen(http.rstrip("/") + "/api/state"))
    ids = [u["id"] for u in roster["uavs"]]
    assert ids == [u["id"] for u in state["uavs"]], f"roster {ids} is not the fleet"
    last = None
    for _ in range(20):
        frame = next(frames)
        if frame["kind"] == "roster":
            roster = frame
            continue
        if frame["kind"] == "reservations":
            assert isinstance(frame["reservations"], list)
            continue
        assert frame["roster_version"] == roster["roster_version"], "a tick of an unknown roster"
        assert last is None or frame["tick"] > last, "ticks go back"
        last = frame["tick"]
        assert frame["fleet"] == len(roster["uavs"]) == len(frame["uavs"]), "records missing"
        assert [u["index"] for u in frame["uavs"]] == list(range(len(roster["uavs"])))
        for u in frame["uavs"]:
            assert all(math.isfinite(x) for x in u["p"] + u["v"] + u["u"] + u["target"]), u
    stream.close()
    # A viewport around the first UAV holds it, and the frames say they are filtered.
    x, y = next(u for u in state["uavs"])["p"]
    stream = Stream(f"{ws}&bbox={x - 50},{y - 50},{x + 50},{y + 50}")
    frames = iter(stream)
    assert next(frames)["kind"] == "roster"
    tick = next(f for f in frames if f["kind"] == "tick")
    assert tick["filtered"] and 1 <= len(tick["uavs"]) <= tick["fleet"], tick["uavs"]
    stream.close()
    print(f"binary stream: {len(roster['uavs'])} UAVs, 20 frames and a viewport decoded and checked")


def main(argv):
    if len(argv) == 2 and argv[0] == "--check":
        try:
            check(argv[1])
        except AssertionError as e:
            print(f"error: binary stream: {e}", file=sys.stderr)
            return 1
        return 0
    if not argv or argv[0].startswith("-"):
        print(__doc__, file=sys.stderr)
        return 2
    frames = int(argv[2]) if len(argv) == 3 and argv[1] == "--frames" else 20
    stream = Stream(argv[0])
    for _ in range(frames):
        message = stream.message()
        if isinstance(message, str):  # the JSON stream (`/ws` without format=bin)
            print(f"json snapshot: {len(message.encode())} bytes")
            continue
        frame, size = decode(message), len(message)
        if frame["kind"] == "roster":
            print(f"roster {frame['roster_version']}: {len(frame['uavs'])} UAVs, {size} bytes")
        elif frame["kind"] == "reservations":
            print(f"reservations {frame['version']}: {len(frame['reservations'])} single-file sections, {size} bytes")
        elif frame["kind"] == "region":
            print(f"region {frame['region']} tick {frame['tick']}: {len(frame['uavs'])} UAVs, {size} bytes")
        else:
            print(f"tick {frame['tick']} t={frame['time']:.2f} s: {len(frame['uavs'])} of {frame['fleet']} UAVs, {size} bytes")
    stream.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
