#!/usr/bin/env python3
"""A lightposed subscriber in the Python standard library only.

It exists to prove that a client that is not ours reads the stream: it
binds a UDP port, decodes every datagram as one JSON object, checks the
fields FORMATS.md promises (class, seq, t on every message; POSE fields
numbers or null; no NaN), and prints a one-line JSON summary.

    python3 tests/python/subscriber.py --port 17150 --seconds 10 --print

With --port 0 (the default) it binds a free port and prints that port on
its first line, so a test can point the daemon at it.
"""
import argparse
import json
import math
import socket
import sys
import time

POSE_FIELDS = ("x", "y", "z", "pitch", "yaw", "surge")


def reject_constant(name):
    raise ValueError("non-finite number %s" % name)


def check(msg, problems):
    for key in ("class", "seq", "t"):
        if key not in msg:
            problems.append("%s message without %s" % (msg.get("class"), key))
    if not isinstance(msg.get("seq"), int):
        problems.append("seq is not an integer: %r" % (msg.get("seq"),))
    if msg.get("class") == "POSE":
        if not isinstance(msg.get("status"), str):
            problems.append("POSE without a status word")
        for f in POSE_FIELDS:
            v = msg.get(f)
            if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v)):
                problems.append("POSE %s = %r" % (f, v))
        if not isinstance(msg.get("time"), (int, float)):
            problems.append("POSE without wall-clock time")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--print", action="store_true", help="print every message")
    a = ap.parse_args()

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    s.bind((a.host, a.port))
    print(s.getsockname()[1], flush=True)
    s.settimeout(0.1)

    counts, problems = {}, []
    pose_seqs, ok_poses, status_times = [], 0, []
    end = time.monotonic() + a.seconds
    while time.monotonic() < end:
        try:
            data = s.recv(65536)
        except socket.timeout:
            continue
        try:
            msg = json.loads(data.decode("utf-8"), parse_constant=reject_constant)
        except ValueError as e:
            problems.append("not JSON: %s" % e)
            continue
        if not isinstance(msg, dict):
            problems.append("not a JSON object")
            continue
        cls = msg.get("class")
        counts[cls] = counts.get(cls, 0) + 1
        check(msg, problems)
        if cls == "POSE":
            pose_seqs.append(msg["seq"])
            ok_poses += msg.get("status") == "ok" and msg.get("x") is not None
        elif cls == "STATUS":
            status_times.append(time.monotonic())
        if a.print:
            print(json.dumps(msg), flush=True)

    increasing = all(b > a_ for a_, b in zip(pose_seqs, pose_seqs[1:]))
    print(json.dumps({
        "counts": counts,
        "ok_poses": ok_poses,
        "seq_increasing": increasing,
        "status_gaps": [round(b - a_, 3) for a_, b in zip(status_times, status_times[1:])],
        "problems": problems[:10],
    }), flush=True)
    return 0 if not problems else 1


if __name__ == "__main__":
    sys.exit(main())
