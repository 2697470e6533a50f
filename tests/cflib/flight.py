#!/usr/bin/env python3
"""A short flight of a simulated Crazyflie (cfsim) with Bitcraze's own Python client, cflib.

Run by scripts/cflib-check against `cfsim --count 1`. Through cflib's UDP driver
(`udp://HOST:PORT`, one CRTP packet per datagram) it connects, downloads the log and param TOCs,
streams a log block (stateEstimate.x/y/z and kalman.varPX/varPY/varPZ), resets the estimator and
waits for it as cflib's examples do, reads the supervisor bits, sends an arming request, takes
off with the high-level commander, goes to a point and lands, checking the logged position and the
supervisor bits at each step. Exits 1 with a message naming the failed step.
"""

import argparse
import logging
import os
import sys
import threading
import time

import cflib.crtp
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from cflib.crazyflie.syncLogger import SyncLogger
from cflib.crtp.crtpstack import CRTPPort

# Supervisor bitfield (crazyflie-firmware supervisor.c, cflib/crazyflie/supervisor.py).
CAN_BE_ARMED, IS_ARMED, AUTO_ARMED, CAN_FLY, IS_FLYING, IS_LOCKED = 1, 2, 4, 8, 16, 64
HL_FINISHED = 0x200
# The supervisor's arming command and the response flag of its answers (crtp_supervisor.h).
CMD_ARM_SYSTEM, CMD_RESPONSE = 0x01, 0x80

# The log block of the flight: the position and the variances cflib's examples wait on.
LOGGED = tuple(f"stateEstimate.{a}" for a in "xyz") + tuple(f"kalman.varP{a}" for a in "XYZ")
TAKE_OFF_HEIGHT = 0.5
GO_TO = (0.5, 0.3, 0.7)
# How close (m) a finished high-level trajectory ends to its target, and what counts as down.
TOLERANCE = 0.03
ON_GROUND = 0.05
# The supervisor calls a Crazyflie flying until 2 s after its thrust went to idle.
IS_FLYING_HYSTERESIS = 2.0


class Failure(Exception):
    """A check that did not hold."""


def check(condition, message):
    if not condition:
        raise Failure(message)


def step(text):
    print(f"cflib-check: {text}", flush=True)


class Latest:
    """The newest sample of a log block, filled from cflib's receive thread."""

    def __init__(self):
        self._lock = threading.Lock()
        self.data = None
        self.count = 0

    def on_data(self, timestamp, data, logconf):
        with self._lock:
            self.data = dict(data)
            self.count += 1

    def get(self):
        with self._lock:
            return self.data, self.count


def wait_until(what, predicate, timeout, describe):
    """Poll `predicate` every 20 ms until it holds; fail with `describe()` after `timeout` s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.02)
    raise Failure(f"{what} within {timeout} s; last: {describe()}")


def bits(cf):
    """The supervisor bitfield as cflib reads it (the answer must carry the response flag)."""
    return cf.supervisor.read_bitfield()


def names(bitfield, cf):
    return f"{bitfield:#06x} {cf.supervisor.decode_bitfield(bitfield)}"


def check_tocs(cf):
    log_toc, param_toc = cf.log.toc.toc, cf.param.toc.toc
    log_vars = {f"{g}.{n}" for g, vs in log_toc.items() for n in vs}
    params = {f"{g}.{n}" for g, vs in param_toc.items() for n in vs}
    for var in LOGGED + ("supervisor.info",):
        check(var in log_vars, f"{var} missing from the log TOC ({len(log_vars)} variables)")
    for p in ["commander.enHighLevel", "kalman.resetEstimation"]:
        check(p in params, f"{p} missing from the param TOC ({len(params)} params)")
    step(f"TOCs downloaded: {len(log_vars)} log variables, {len(params)} params")


def wait_for_position_estimator(scf):
    """cflib's examples: the last 10 samples of each variance spread by less than 0.001 (they log
    every 500 ms; 100 ms keeps the check short)."""
    conf = LogConfig(name="Kalman Variance", period_in_ms=100)
    for axis in "XYZ":
        conf.add_variable(f"kalman.varP{axis}", "float")
    history = {axis: [1000.0] * 10 for axis in "XYZ"}
    deadline = time.monotonic() + 10.0
    with SyncLogger(scf, conf) as logger:
        for _, data, _ in logger:
            for axis in "XYZ":
                history[axis].append(data[f"kalman.varP{axis}"])
                history[axis].pop(0)
            if all(max(h) - min(h) < 0.001 for h in history.values()):
                return {axis: h[-1] for axis, h in history.items()}
            check(time.monotonic() < deadline, f"estimator not settled in 10 s: {history}")
    raise Failure("the variance log stopped")


def fly(uri):
    # The UDP driver is one of cflib's default drivers: no flag or environment variable needed.
    cflib.crtp.init_drivers()
    cf = Crazyflie()  # no TOC cache: both TOCs are downloaded
    arm_answers = []

    def on_supervisor(pk):
        # The raw answers of the supervisor's command channel (cflib only logs the arming answer).
        if pk.channel == 1:
            arm_answers.append(bytes(pk.data))

    cf.add_port_callback(CRTPPort.SUPERVISOR, on_supervisor)
    with SyncCrazyflie(uri, cf=cf) as scf:
        version = cf.platform.get_protocol_version()
        check(version >= 12, f"protocol version {version}: cflib would not use the supervisor port")
        step(f"connected to {uri} (CRTP protocol {version})")
        check_tocs(cf)
        scf.wait_for_params()
        cf.param.set_value("commander.enHighLevel", "1")

        position = Latest()
        conf = LogConfig(name="Position", period_in_ms=50)
        for var in LOGGED:
            conf.add_variable(var, "float")
        cf.log.add_config(conf)
        conf.data_received_cb.add_callback(position.on_data)
        conf.start()
        wait_until("log data", lambda: position.get()[1] >= 5, 5.0, position.get)
        data, _ = position.get()
        step(f"log block streaming: {data}")

        def xyz():
            d, _ = position.get()
            return d["stateEstimate.x"], d["stateEstimate.y"], d["stateEstimate.z"]

        def arrived(target):
            # Near the target with the high-level trajectory finished (near alone would pass
            # while still moving).
            def at():
                near = all(abs(a - b) < TOLERANCE for a, b in zip(xyz(), target))
                return near and bits(cf) & HL_FINISHED

            return at

        def where():
            return f"{xyz()}, {names(bits(cf), cf)}"

        start = xyz()
        check(abs(start[2]) < ON_GROUND, f"not on the ground at the start: {start}")

        cf.param.set_value("kalman.resetEstimation", "1")
        time.sleep(0.1)
        cf.param.set_value("kalman.resetEstimation", "0")
        settled = wait_for_position_estimator(scf)
        check(all(v < 0.001 for v in settled.values()), f"variances still large: {settled}")
        step(f"estimator settled: {settled}")

        b = bits(cf)
        check(not b & (IS_FLYING | IS_LOCKED), f"flying or locked on the ground: {names(b, cf)}")
        if b & AUTO_ARMED:
            check(b & IS_ARMED and b & CAN_FLY, f"auto-armed but not ready: {names(b, cf)}")
        else:
            check(
                b & CAN_BE_ARMED and not b & (IS_ARMED | CAN_FLY), f"not waiting for arming: {names(b, cf)}"
            )
        step(f"supervisor before arming: {names(b, cf)}")
        cf.supervisor.send_arming_request(True)
        wait_until("an arming answer", lambda: arm_answers, 2.0, lambda: arm_answers)
        expected = bytes([CMD_RESPONSE | CMD_ARM_SYSTEM, 1, 1])
        check(arm_answers[0] == expected, f"arming answer {arm_answers[0].hex()}, expected {expected.hex()}")
        wait_until(
            "armed and allowed to fly",
            lambda: bits(cf) & (IS_ARMED | CAN_FLY) == IS_ARMED | CAN_FLY,
            2.0,
            lambda: names(bits(cf), cf),
        )
        step(f"armed: {names(bits(cf), cf)}")

        cf.high_level_commander.takeoff(TAKE_OFF_HEIGHT, 1.5)
        target = (start[0], start[1], TAKE_OFF_HEIGHT)
        wait_until(f"take-off to {target}", arrived(target), 6.0, where)
        b = bits(cf)
        check(b & IS_FLYING and b & CAN_FLY, f"up but not flying: {names(b, cf)}")
        step(f"took off to {xyz()}: {names(b, cf)}")

        cf.high_level_commander.go_to(*GO_TO, 0.0, 2.0)
        wait_until(f"go-to {GO_TO}", arrived(GO_TO), 7.0, where)
        check(bits(cf) & IS_FLYING, f"not flying at the go-to point: {names(bits(cf), cf)}")
        step(f"reached {xyz()}")

        cf.high_level_commander.land(0.0, 1.5)
        wait_until("landing", lambda: xyz()[2] < ON_GROUND, 6.0, where)
        landed = time.monotonic()
        step(f"landed at {xyz()}: {names(bits(cf), cf)}")
        wait_until(
            "the supervisor to call it landed",
            lambda: not bits(cf) & IS_FLYING,
            IS_FLYING_HYSTERESIS + 2.0,
            lambda: names(bits(cf), cf),
        )
        b = bits(cf)
        check(not b & IS_LOCKED and b & CAN_FLY, f"not ready after landing: {names(b, cf)}")
        step(f"not flying {time.monotonic() - landed:.1f} s after touching down: {names(b, cf)}")
        _, samples = position.get()
        conf.stop()
    step(f"flight passed ({samples} log samples)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("uri", help="e.g. udp://127.0.0.1:19850")
    parser.add_argument("--deadline", type=float, default=60.0, help="give up after this many seconds")
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)

    def give_up():
        print(f"cflib-check: FAILED: no result within {args.deadline} s", file=sys.stderr, flush=True)
        os._exit(1)

    watchdog = threading.Timer(args.deadline, give_up)
    watchdog.daemon = True
    watchdog.start()
    started = time.monotonic()
    try:
        fly(args.uri)
    except Failure as e:
        print(f"cflib-check: FAILED: {e}", file=sys.stderr, flush=True)
        return 1
    except Exception as e:  # a cflib error (e.g. the connection failed) is a failure too
        print(f"cflib-check: FAILED: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
        return 1
    step(f"done in {time.monotonic() - started:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
