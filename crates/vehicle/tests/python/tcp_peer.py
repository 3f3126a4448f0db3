"""A stand-in autopilot over TCP, written with pymavlink: the far end of a
`tcpout` link (MODE server: it listens, as mavlink-router's and BlueOS's
TCP servers do) or of a `tcpin` link (MODE client: it connects to PORT).

On each connection it sends, every 50 ms, an autopilot HEARTBEAT and an
ATTITUDE (pitch 0.1 rad), decodes whatever comes with pymavlink (CRC
checked) and counts VISION_POSITION_ESTIMATEs and HEARTBEATs per
connection. A server given CLOSE_AFTER closes its first connection once
that many estimates came and accepts the next (the link must reconnect).
It prints {"port": N} first and {"done": ...} once the last connection
got N_POSITIONS estimates, or at the deadline.

usage: tcp_peer.py server N_POSITIONS TIMEOUT_S [CLOSE_AFTER]
       tcp_peer.py client PORT N_POSITIONS TIMEOUT_S
"""

import json
import os
import socket
import sys
import time

os.environ["MAVLINK20"] = "1"  # before pymavlink is imported
from pymavlink.dialects.v20 import ardupilotmega as apm  # noqa: E402


def frames(tx):
    t = int(time.monotonic() * 1000) & 0xFFFFFFFF
    msgs = [
        tx.heartbeat_encode(
            apm.MAV_TYPE_SUBMARINE, apm.MAV_AUTOPILOT_ARDUPILOTMEGA,
            0, 0, apm.MAV_STATE_ACTIVE,
        ),
        tx.attitude_encode(t, 0.0, 0.1, 0.5, 0.0, 0.0, 0.0),
    ]
    return b"".join(m.pack(tx) for m in msgs)


def serve(conn, want, deadline, tx, stats):
    """Talk on one connection until `want` estimates came (or it closed,
    or the deadline); returns the estimates counted."""
    rx = apm.MAVLink(None)
    rx.robust_parsing = True
    conn.settimeout(0.02)
    positions, beats, next_send = 0, 0, 0.0
    while time.monotonic() < deadline and positions < want:
        if time.monotonic() >= next_send:
            try:
                conn.sendall(frames(tx))
            except OSError:
                break
            next_send = time.monotonic() + 0.05
        try:
            data = conn.recv(4096)
        except socket.timeout:
            continue
        except OSError:
            break
        if not data:
            break
        for m in rx.parse_buffer(data) or []:
            kind = m.get_type()
            if kind == "BAD_DATA":
                stats["bad_data"] += 1
            elif kind == "VISION_POSITION_ESTIMATE":
                positions += 1
            elif kind == "HEARTBEAT":
                beats += 1
    stats["receive_errors"] += rx.total_receive_errors
    stats["heartbeats"].append(beats)
    return positions


def main():
    mode = sys.argv[1]
    tx = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    stats = {"bad_data": 0, "receive_errors": 0, "heartbeats": []}
    per_conn = []
    if mode == "server":
        want, timeout = int(sys.argv[2]), float(sys.argv[3])
        close_after = int(sys.argv[4]) if len(sys.argv) > 4 else None
        deadline = time.monotonic() + timeout
        srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        srv.bind(("127.0.0.1", 0))
        srv.listen(4)
        srv.settimeout(0.1)
        print(json.dumps({"port": srv.getsockname()[1]}), flush=True)
        while time.monotonic() < deadline:
            try:
                conn, _ = srv.accept()
            except socket.timeout:
                continue
            first = close_after is not None and not per_conn
            n = serve(conn, close_after if first else want, deadline, tx, stats)
            conn.close()
            per_conn.append(n)
            if not first and n >= want:
                break
    else:
        port, want, timeout = int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
        deadline = time.monotonic() + timeout
        print(json.dumps({"port": port}), flush=True)
        conn = socket.create_connection(("127.0.0.1", port), timeout=5)
        per_conn.append(serve(conn, want, deadline, tx, stats))
        conn.close()
    stats.update({"done": True, "positions": per_conn})
    print(json.dumps(stats), flush=True)


if __name__ == "__main__":
    main()
