"""A stand-in autopilot written with pymavlink, for the interop test.

It listens on a UDP port of its own (printed first, as {"port": N}),
decodes with pymavlink whatever arrives (MAVLink 2, CRC checked by
pymavlink) and prints each message as one JSON line; to every peer that has
spoken it sends, every 50 ms, ATTITUDE, VFR_HUD, GLOBAL_POSITION_INT,
SCALED_PRESSURE2 and an autopilot HEARTBEAT with the values below. It stops
when it has seen enough of each message (two HEARTBEATs from each
component), or at the deadline, and prints
{"done": ...} with its counts and pymavlink's receive-error count.

With PASSPHRASE it signs what it sends (link id 7) with the key
SHA-256(PASSPHRASE), as MAVProxy's `signing setup` makes it, and checks the
signature of what it receives (pymavlink refuses frames not signed with
the key: they count as bad data); "done" then also has pymavlink's
signature counts.

usage: mav_peer.py N_POSITIONS TIMEOUT_S [PASSPHRASE]
(MAV_PEER_COMPONENTS: how many components of ours to expect, default 2.)
"""

import hashlib
import json
import math
import os
import socket
import sys
import time

os.environ["MAVLINK20"] = "1"  # before pymavlink is imported
from pymavlink.dialects.v20 import ardupilotmega as apm  # noqa: E402

# What the autopilot says (the Rust side checks it gets exactly these).
ROLL, PITCH, YAW = 0.05, 0.1, math.radians(-160.0)
VFR_ALT = -2.5  # m (2.5 m deep)
REL_ALT_MM = -2600  # mm (2.6 m deep)
TEMP_CDEG = 1234  # 12.34 degC


def clean(v):
    """JSON has no NaN: a non-finite float is reported as a string."""
    if isinstance(v, float) and not math.isfinite(v):
        return repr(v)
    if isinstance(v, list):
        return [clean(x) for x in v]
    return v


def autopilot_frames(tx):
    t = int(time.monotonic() * 1000) & 0xFFFFFFFF
    # The HEARTBEAT first: it tells the reader who the autopilot is, and
    # nothing else is taken before (no readings are refused here).
    msgs = [
        tx.heartbeat_encode(
            apm.MAV_TYPE_SUBMARINE,
            apm.MAV_AUTOPILOT_ARDUPILOTMEGA,
            0,
            0,
            apm.MAV_STATE_ACTIVE,
        ),
        tx.attitude_encode(t, ROLL, PITCH, YAW, 0.0, 0.0, 0.0),
        tx.vfr_hud_encode(0.0, 0.0, 200, 0, VFR_ALT, 0.0),
        tx.global_position_int_encode(t, 0, 0, 0, REL_ALT_MM, 0, 0, 0, 0),
        tx.scaled_pressure2_encode(t, 1030.0, 0.0, TEMP_CDEG),
    ]
    return [m.pack(tx) for m in msgs]


def main():
    n_pos = int(sys.argv[1])
    deadline = time.monotonic() + float(sys.argv[2])
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.02)
    print(json.dumps({"port": sock.getsockname()[1]}), flush=True)
    rx = apm.MAVLink(None)
    rx.robust_parsing = True
    tx = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    if len(sys.argv) > 3:
        key = hashlib.sha256(sys.argv[3].encode()).digest()
        # As mavutil's setup_signing: timestamps in 10 us since 2015.
        now = int((time.time() - 1420070400) * 100 * 1000)
        tx.signing.secret_key, tx.signing.link_id = key, 7
        tx.signing.sign_outgoing, tx.signing.timestamp = True, now
        rx.signing.secret_key = key
    peers, counts, bad, next_send, rounds = set(), {}, 0, 0.0, 0
    beats = {}  # HEARTBEATs per (system, component) that sent them
    while time.monotonic() < deadline:
        try:
            data, addr = sock.recvfrom(4096)
        except socket.timeout:
            data = None
        if data:
            peers.add(addr)
            for m in rx.parse_buffer(data) or []:
                kind = m.get_type()
                if kind == "BAD_DATA":
                    bad += 1
                    continue
                counts[kind] = counts.get(kind, 0) + 1
                if kind == "HEARTBEAT":
                    key = (m.get_srcSystem(), m.get_srcComponent())
                    beats[key] = beats.get(key, 0) + 1
                line = {
                    "type": kind,
                    "sys": m.get_srcSystem(),
                    "comp": m.get_srcComponent(),
                    "seq": m.get_seq(),
                    "v2": m.get_msgbuf()[0] == 0xFD,
                    # Verified with the key (only with a PASSPHRASE), and the
                    # frame's own "signed" flag.
                    "signed": bool(m.get_signed()),
                    "flag_signed": bool(m.get_msgbuf()[2] & 1),
                    "link_id": m.get_link_id(),
                    "fields": {k: clean(v) for k, v in m.to_dict().items()},
                }
                print(json.dumps(line), flush=True)
        if peers and time.monotonic() >= next_send:
            frames = autopilot_frames(tx)
            for p in peers:
                # One frame per datagram, and every other round all in one.
                if rounds % 2:
                    sock.sendto(b"".join(frames), p)
                else:
                    for f in frames:
                        sock.sendto(f, p)
            rounds += 1
            next_send = time.monotonic() + 0.05
        if (
            counts.get("VISION_POSITION_ESTIMATE", 0) >= n_pos
            and counts.get("VISION_SPEED_ESTIMATE", 0) >= 1
            # Two from each of the test's two components: four in all
            # could be three of one and one of the other (failed once).
            and len(beats) >= int(os.environ.get("MAV_PEER_COMPONENTS", "2"))
            and min(beats.values()) >= 2
            and rounds >= 4
        ):
            break
    done = {
        "done": True,
        "counts": counts,
        "bad_data": bad,
        "receive_errors": rx.total_receive_errors,
        "rounds": rounds,
        "good_signatures": rx.signing.goodsig_count,
        "bad_signatures": rx.signing.badsig_count,
        "unsigned": rx.signing.unsigned_count,
    }
    print(json.dumps(done), flush=True)


if __name__ == "__main__":
    main()
