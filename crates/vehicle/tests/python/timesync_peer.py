"""A stand-in autopilot, written with pymavlink, that asks for TIMESYNC as
PX4 and ArduPilot do: once our HEARTBEAT has come it sends its own
HEARTBEAT and a TIMESYNC request (tc1 = 0, ts1 = its CLOCK_MONOTONIC in
ns) every 50 ms, and checks each answer: ts1 must be one of its requests,
tc1 the answerer's time in ns, which on one machine must lie between the
request's sending and the answer's arrival on CLOCK_MONOTONIC (the clock
the daemon stamps live frames, so VISION_POSITION_ESTIMATE.usec, on).

It prints {"port": N} first and {"done": ...} at the end, after N answers
or at the deadline.

usage: timesync_peer.py N_ANSWERS TIMEOUT_S
"""

import json
import os
import socket
import sys
import time

os.environ["MAVLINK20"] = "1"  # before pymavlink is imported
from pymavlink.dialects.v20 import ardupilotmega as apm  # noqa: E402


def main():
    want = int(sys.argv[1])
    deadline = time.monotonic() + float(sys.argv[2])
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.01)
    print(json.dumps({"port": sock.getsockname()[1]}), flush=True)
    rx = apm.MAVLink(None)
    rx.robust_parsing = True
    tx = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    peer, asked, next_send = None, {}, 0.0
    answers, unmatched, outside = [], 0, 0
    while time.monotonic() < deadline and len(answers) < want:
        try:
            data, addr = sock.recvfrom(4096)
        except socket.timeout:
            data = None
        if data:
            peer = addr
            arrived = time.monotonic_ns()
            for m in rx.parse_buffer(data) or []:
                if m.get_type() != "TIMESYNC":
                    continue
                sent = asked.get(m.ts1)
                if sent is None:
                    unmatched += 1
                    continue
                if not sent <= m.tc1 <= arrived:
                    outside += 1
                answers.append(
                    {"ts1": m.ts1, "tc1": m.tc1, "rtt_ns": arrived - sent,
                     "comp": m.get_srcComponent()}
                )
        if peer and time.monotonic() >= next_send:
            beat = tx.heartbeat_encode(
                apm.MAV_TYPE_SUBMARINE, apm.MAV_AUTOPILOT_ARDUPILOTMEGA,
                0, 0, apm.MAV_STATE_ACTIVE,
            )
            sock.sendto(beat.pack(tx), peer)
            ts1 = time.monotonic_ns()
            asked[ts1] = ts1
            sock.sendto(tx.timesync_encode(0, ts1).pack(tx), peer)
            next_send = time.monotonic() + 0.05
    done = {
        "done": True,
        "asked": len(asked),
        "answers": answers,
        "unmatched": unmatched,
        "outside": outside,
        "receive_errors": rx.total_receive_errors,
    }
    print(json.dumps(done), flush=True)


if __name__ == "__main__":
    main()
