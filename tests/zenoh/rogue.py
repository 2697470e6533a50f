"""A rogue Zenoh peer in a process of its own, written with Zenoh's stock Python client: it connects
to a region server's endpoint (with no certificate, or with a certificate of another region) and
tries what a review found a peer could do to an unsecured region network. It prints one JSON object
saying what it saw; the Rust test (tests/server_region_security.rs) checks the servers' side.

usage: rogue.py ENDPOINT[,ENDPOINT...] PREFIX TARGET [--ca CA --cert CERT --key KEY --as REGION]

While its queryable on the target's API is declared it prints the line QUERYABLE and waits 3 s, so
the test can ask another region about the target's UAVs meanwhile.
"""

import argparse
import json
import sys
import time

import zenoh


def config(args):
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps(args.endpoint.split(",")))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    if args.ca:
        tls = {
            "root_ca_certificate": args.ca,
            "verify_name_on_connect": False,
        }
        if args.cert:
            tls.update(connect_certificate=args.cert, connect_private_key=args.key, enable_mtls=True)
        conf.insert_json5("transport/link/tls", json.dumps(tls))
    return conf


def ask(session, key, request):
    """Status of the first reply to `request` on `key`, or None if nobody answered in 2 s."""
    for reply in session.get(key, payload=json.dumps(request), timeout=2.0):
        if reply.ok is not None:
            try:
                return json.loads(reply.ok.payload.to_bytes())["status"]
            except (ValueError, KeyError):
                return "unreadable"
    return None


def release(target, sender, uav_id, p):
    return json.dumps({
        "kind": "release", "from": sender, "to": target, "id": uav_id, "seq": 1,
        "uav": {"p": p, "v": [0.0, 0.0], "goal": None, "policy": "pd", "link": None, "airborne": True},
    })


def offer(target, sender, uav_id, seq, p):
    return json.dumps({
        "kind": "offer", "from": sender, "to": target, "id": uav_id, "seq": seq,
        "uav": {"p": p, "v": [0.0, 0.0], "goal": None, "policy": "pd", "link": None, "airborne": True},
    })


def phantom_states(region, count, x0):
    """A state message (wire format 1) of `count` UAVs in a line at x0.. (the review's wall)."""
    import struct
    name = region.encode()
    out = bytearray(struct.pack("<BBHIQdf", 1, 4, len(name), count, 1, 0.05, 0.0))
    out += name
    for k in range(count):
        uav_id = f"phantom{k}".encode()
        out += struct.pack("<H", len(uav_id)) + uav_id
        out += struct.pack("<8f", x0 + 0.1 * k, 0.0, 0, 0, 0, 0, 0, 0)
        out += struct.pack("<BBH", 0, 0, 0)
    return bytes(out)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("endpoint")
    parser.add_argument("prefix")
    parser.add_argument("target")
    parser.add_argument("--ca")
    parser.add_argument("--cert")
    parser.add_argument("--key")
    parser.add_argument("--as", dest="sender", default="east")
    args = parser.parse_args()
    p, t, me = args.prefix, args.target, args.sender
    seen = {}
    with zenoh.open(config(args)) as session:
        deadline = time.time() + 3.0
        while time.time() < deadline and not list(session.info.peers_zid()):
            time.sleep(0.05)
        seen["connected"] = bool(list(session.info.peers_zid()))
        # 1. Commands without the token: on the API key as it was before regions were secured
        #    (`PREFIX/region/NAME/api`), as the sender region, and as the target itself.
        # A request travels typed (its route and data): the emergency stop has no data.
        stop = {"request": {"route": "stop_fleet"}}
        seen["stop_on_the_bare_key"] = ask(session, f"{p}/region/{t}/api", stop)
        seen["stop_as_sender"] = ask(session, f"{p}/region/{t}/api/{me}", stop)
        seen["stop_as_target"] = ask(session, f"{p}/region/{t}/api/{t}", stop)
        # The audit log is no request of the wire (only the routes that travel between regions are).
        seen["audit_read"] = ask(session, f"{p}/region/{t}/api/{me}", {"request": {"route": "audit"}})
        # 2. Forged ownership: an owner token of a higher epoch, a standby token, a mirror.
        owner = session.liveliness().declare_token(f"{p}/region/{t}/owner/999999/rogue")
        standby = session.liveliness().declare_token(f"{p}/region/{t}/standby/0")
        mirror = {"region": t, "epoch": 999999, "tick": 1, "road_version": 1, "uavs": [
            {"id": "invented", "uav": {"p": [9000.0, 9000.0], "v": [0.0, 0.0], "goal": None,
                                       "policy": "pd", "link": None, "airborne": True}}]}
        session.put(f"{p}/region/{t}/mirror", json.dumps(mirror))
        # 3. Forged handovers: unsolicited releases, as the sender and as someone else.
        for k, (sender, uav_id, pos) in enumerate([
            (me, "forged1", [500.0, 500.0]),
            (me, "has space", [21.0, 0.0]),
            (me, "dup", [19.0, 0.5]),
            (t, "selfish", [19.0, -0.5]),
        ]):
            session.put(f"{p}/region/{t}/handover/{sender}", release(t, sender, uav_id, pos))
        # 3b. 250 forged offers as the sender, at safe places in the target's region (a grid 0.5 m
        #     apart): they may reserve room for a while, but not keep a real handover out.
        for k in range(250):
            pos = [1.0 + 0.5 * (k % 36), -1.5 + 0.5 * (k // 36)]
            session.put(f"{p}/region/{t}/handover/{me}", offer(t, me, f"offered{k}", 1000 + k, pos))
        # 4. Oversized and invented: one message of 300,000 UAVs (12 MiB) as the sender, and 200
        #    regions the road does not have.
        session.put(f"{p}/region/{me}/state", phantom_states(me, 300_000, 9000.0))
        for k in range(200):
            session.put(f"{p}/region/invented{k}/state", phantom_states(f"invented{k}", 2_000, 0.0))
        # 5. Forged states: a wall of phantoms as the target and as the sender, far away and fast.
        for _ in range(50):
            session.put(f"{p}/region/{t}/state", phantom_states(t, 55, 18.0))
            session.put(f"{p}/region/{me}/state", phantom_states(me, 55, 9000.0))
            time.sleep(0.005)
        # 6. A rogue queryable on the target's API.
        queryable = session.declare_queryable(
            f"{p}/region/{t}/api/*",
            lambda q: q.reply(q.key_expr, json.dumps({"status": 200, "body": "{\"rogue\": true}"})),
        )
        print("QUERYABLE", flush=True)
        time.sleep(3.0)
        owner.undeclare()
        standby.undeclare()
        queryable.undeclare()
    print(json.dumps(seen))


if __name__ == "__main__":
    sys.exit(main())
