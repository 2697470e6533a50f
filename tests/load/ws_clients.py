#!/usr/bin/env python3
"""N binary-stream clients in one process (a load generator for scripts/load-test): each opens
`/ws?format=bin` and drains what the server sends; at the end prints, per client, the tick frames
received. Standard library only; frames are counted from their 2-byte prefix, not decoded.

    python3 tests/load/ws_clients.py ws://127.0.0.1:8080 50 60     # 50 clients for 60 s
"""

import base64
import os
import selectors
import socket
import sys
import time


def open_client(host, port):
    sock = socket.create_connection((host, port), timeout=10)
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall((f"GET /ws?format=bin HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
                  f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
    head = b""
    while b"\r\n\r\n" not in head:
        head += sock.recv(4096)
    status, rest = head.split(b"\r\n", 1)[0], head.split(b"\r\n\r\n", 1)[1]
    if b" 101 " not in status + b" ":
        raise ConnectionError(status.decode(errors="replace"))
    sock.setblocking(False)
    return sock, rest


class Client:
    """Parses frame boundaries only: header bytes, payload length, skip the payload."""

    def __init__(self, sock, rest):
        self.sock, self.buf, self.ticks, self.bytes = sock, bytearray(rest), 0, 0

    def feed(self):
        try:
            chunk = self.sock.recv(1 << 20)
        except BlockingIOError:
            return True
        if not chunk:
            return False
        self.bytes += len(chunk)
        self.buf += chunk
        while len(self.buf) >= 2:
            length, at = self.buf[1] & 0x7F, 2
            if length == 126:
                if len(self.buf) < 4:
                    break
                length, at = int.from_bytes(self.buf[2:4], "big"), 4
            elif length == 127:
                if len(self.buf) < 10:
                    break
                length, at = int.from_bytes(self.buf[2:10], "big"), 10
            if len(self.buf) < at + length:
                break
            if self.buf[0] & 0x0F == 2 and length >= 2 and self.buf[at + 1] == 1:
                self.ticks += 1
            del self.buf[: at + length]
        return True


def main(url, n, seconds):
    host, port = url.split("://", 1)[1].rstrip("/").split(":")
    selector = selectors.DefaultSelector()
    clients = []
    for _ in range(n):
        client = Client(*open_client(host, int(port)))
        clients.append(client)
        selector.register(client.sock, selectors.EVENT_READ, client)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for key, _ in selector.select(timeout=0.5):
            if not key.data.feed():
                selector.unregister(key.fileobj)
    ticks = sorted(c.ticks for c in clients)
    total = sum(c.bytes for c in clients)
    print(f"{n} clients, {seconds} s: tick frames per client min {ticks[0]} median {ticks[n // 2]} "
          f"max {ticks[-1]} ({ticks[n // 2] / seconds:.1f}/s median), {total / seconds / 1e6:.1f} MB/s in all")


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]))
