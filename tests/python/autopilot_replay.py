"""A stand-in ArduSub autopilot written with pymavlink, for the daemon's
end-to-end MAVLink test (crates/daemon/tests/mavlink.rs).

It reads the truth of a frame log (FORMATS.md: one JSON object per line,
`truth` in the beam frame B), talks to a daemon listening on
udpin:127.0.0.1:PORT and, every 20 ms, sends ATTITUDE, GLOBAL_POSITION_INT
(relative_alt, the daemon's default depth), VFR_HUD (as ArduSub with an EKF
origin at sea level) and SCALED_PRESSURE2 computed from the truth at the
log time the daemon is capturing, plus a HEARTBEAT every second (before
every batch until the daemon answers). The log time is read off the
daemon's own messages: the least (arrival - usec) over its
VISION_POSITION_ESTIMATEs (each arrives after its frame's capture, so the
least is the closest); before the first of them the arrival of its first
HEARTBEAT (it starts with the replay), and before that the log's start.

Everything the daemon sends is decoded by pymavlink (MAVLink 2 only, CRC
checked); at the end it judges the VISION_POSITION_ESTIMATEs against the
truth, converted B -> NED with its own few lines (FORMATS.md, "Vehicle
integration"), and prints one JSON line with counts, coverage and p95s
(after a first line {"ready": true} once it is ready to send).

usage: autopilot_replay.py LOG PORT HEADING_DEG BEACON_DEPTH_M WATER_C
       COVER_AFTER_S P95_AFTER_S QUIET_S DEADLINE_S
"""

import bisect
import json
import math
import os
import socket
import sys
import time

os.environ["MAVLINK20"] = "1"  # before pymavlink is imported
from pymavlink.dialects.v20 import ardupilotmega as apm  # noqa: E402


def read_truth(path):
    """[(t, (x, y, z, pitch_deg, yaw_deg))] of the log's frames."""
    out = []
    with open(path) as f:
        for line in f:
            m = json.loads(line)
            if m.get("class") != "FRAME":
                continue
            for k in ("attitude", "depth", "temp_c", "velocity"):
                if m.get(k) is not None:
                    raise SystemExit(f"{path}: frame {m['seq']} carries {k}: not a bare log")
            tr = m["truth"]
            out.append((m["t"], (tr["x"], tr["y"], tr["z"], tr["pitch"], tr["yaw"])))
    return out


def truth_at(truth, t):
    """Linear between frames, clamped at the ends."""
    ts = [x[0] for x in truth]
    k = bisect.bisect_right(ts, t)
    if k == 0:
        return truth[0][1]
    if k >= len(truth):
        return truth[-1][1]
    (t0, a), (t1, b) = truth[k - 1], truth[k]
    w = min(max((t - t0) / (t1 - t0), 0.0), 1.0)
    return tuple(u + w * (v - u) for u, v in zip(a, b))


def wrap180(d):
    r = math.fmod(d, 360.0)
    if r > 180.0:
        r -= 360.0
    if r <= -180.0:
        r += 360.0
    return r


def to_ned(pose, h_deg):
    """FORMATS.md: N = x cos h + y sin h, E = x sin h - y cos h, D = -z
    (the beacon at the origin); heading = h + 180 + yaw; pitch = pitch."""
    x, y, z, pitch, yaw = pose
    h = math.radians(h_deg)
    n = x * math.cos(h) + y * math.sin(h)
    e = x * math.sin(h) - y * math.cos(h)
    return (n, e, -z, pitch, wrap180(h_deg + 180.0 + yaw))


def p95(values):
    """Nearest rank."""
    a = sorted(abs(v) for v in values)
    if not a:
        return None
    return a[max(1, math.ceil(0.95 * len(a))) - 1]


def sensor_messages(tx, pose, args, ms):
    x, y, z, pitch, yaw = pose
    _, _, _, _, heading = to_ned(pose, args["h"])
    depth = args["d_b"] - z  # z = d_b - depth
    return [
        tx.attitude_encode(ms, 0.0, math.radians(pitch), math.radians(heading), 0.0, 0.0, 0.0),
        tx.global_position_int_encode(
            ms, 0, 0, 0, round(-depth * 1000), 0, 0, 0, round(heading % 360 * 100) % 36000
        ),
        tx.vfr_hud_encode(0.0, 0.0, int(heading) % 360, 0, -depth, 0.0),
        tx.scaled_pressure2_encode(ms, 1013.25 + 98.1 * depth, 0.0, round(args["water"] * 100)),
    ]


def run(args, truth):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.005)
    # The caller starts the daemon on this line: pymavlink is imported and
    # the log read, so the first frames already find readings.
    print(json.dumps({"ready": True}), flush=True)
    daemon = ("127.0.0.1", args["port"])
    rx = apm.MAVLink(None)
    rx.robust_parsing = True
    tx = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    heard = {"vpe": [], "counts": {}, "bad": 0, "v1": 0, "arrival": {}}
    origin, last_rx, next_send, next_beat = None, None, 0.0, 0.0
    start = time.monotonic()
    while time.monotonic() - start < args["deadline"]:
        if last_rx is not None and time.monotonic() - last_rx > args["quiet"]:
            break
        try:
            data, _ = sock.recvfrom(65536)
        except (socket.timeout, ConnectionRefusedError):
            data = None
        now = time.monotonic()
        if data:
            last_rx = now
            for m in rx.parse_buffer(data) or []:
                kind = m.get_type()
                if kind == "BAD_DATA":
                    heard["bad"] += 1
                    continue
                if m.get_msgbuf()[0] != 0xFD:  # not a MAVLink 2 frame
                    heard["v1"] += 1
                heard["counts"][kind] = heard["counts"].get(kind, 0) + 1
                if kind == "VISION_POSITION_ESTIMATE":
                    o = now - m.usec / 1e6
                    origin = o if origin is None else min(origin, o)
                    heard["vpe"].append(m)
                    heard["arrival"][m.usec] = now - start
                elif kind == "HEARTBEAT" and origin is None:
                    origin = now
        if now >= next_send:
            next_send = now + 0.02
            # A HEARTBEAT every second, as ArduSub sends it; until the
            # daemon answers, one before every batch. The daemon takes
            # readings only from an autopilot it has heard, and answers
            # only then: a first HEARTBEAT lost to a daemon not yet bound
            # would otherwise leave its first second without readings and
            # this clock a second behind the replay.
            if origin is None or now >= next_beat:
                next_beat = now + 1.0
                hb = tx.heartbeat_encode(
                    apm.MAV_TYPE_SUBMARINE, apm.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 19, apm.MAV_STATE_ACTIVE
                )
                sock.sendto(hb.pack(tx), daemon)
            t = 0.0 if origin is None else now - origin
            ms = int((now - start) * 1000) & 0xFFFFFFFF
            for m in sensor_messages(tx, truth_at(truth, t), args, ms):
                sock.sendto(m.pack(tx), daemon)
    heard["origin"] = None if origin is None else origin - start
    return heard


def judge(args, truth, heard):
    t0 = truth[0][0]
    by_usec = {m.usec: m for m in heard["vpe"]}
    cover = [t for t, _ in truth if t >= t0 + args["cover_after"]]
    covered = sum(1 for t in cover if round(t * 1e6) in by_usec)
    errs = [[] for _ in range(5)]
    # Each judged frame's log time, how late its estimate arrived against
    # the least (the stand-in's clock), and its errors: the worst of them
    # are printed, so that a failure says when and how.
    frames = []
    for t, pose in truth:
        m = by_usec.get(round(t * 1e6))
        if t < t0 + args["p95_after"] or m is None:
            continue
        want = to_ned(pose, args["h"])
        got = (m.x, m.y, m.z, math.degrees(m.pitch), math.degrees(m.yaw))
        e = []
        for k in range(5):
            d = got[k] - want[k]
            e.append(wrap180(d) if k == 4 else d)
            errs[k].append(e[-1])
        late = heard["arrival"][m.usec] - m.usec / 1e6 - (heard["origin"] or 0.0)
        frames.append({"t": t, "late_s": round(late, 4), "err": [round(v, 3) for v in e]})
    worst = sorted(frames, key=lambda f: -max(abs(f["err"][0]), abs(f["err"][1])))[:8]
    finite = all(
        all(math.isfinite(c) for c in m.covariance) and not math.isnan(m.covariance[0])
        for m in heard["vpe"]
    )
    names = ["north", "east", "down", "pitch", "heading"]
    return {
        "done": True,
        "counts": heard["counts"],
        "bad": heard["bad"],
        "v1": heard["v1"],
        "covariance_finite": finite,
        "frames": len(cover),
        "covered": covered,
        "judged": len(errs[0]),
        "p95": {n: p95(e) for n, e in zip(names, errs)},
        "worst": worst,
    }


def main():
    a = sys.argv[1:]
    args = {
        "port": int(a[1]),
        "h": float(a[2]),
        "d_b": float(a[3]),
        "water": float(a[4]),
        "cover_after": float(a[5]),
        "p95_after": float(a[6]),
        "quiet": float(a[7]),
        "deadline": float(a[8]),
    }
    truth = read_truth(a[0])
    heard = run(args, truth)
    print(json.dumps(judge(args, truth, heard)), flush=True)


if __name__ == "__main__":
    main()
