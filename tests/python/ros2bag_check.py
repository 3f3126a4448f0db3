"""Read a ROS 2 bag of `lightpose convert --ros2` with rosbags (AnyReader,
its types built from the bag's own ros2msg schemas) and the `mcap`
package, and check every message against the POSE lines it came from.

Written from docs/ros2.md and MODEL.md, not from lightpose's code: the
orientation is base_link (FLU) in B, i.e. R_BV = R0 Rz(yaw) Ry(pitch)
Rx(roll) with R0 = diag(-1, 1, -1) and its y and z columns negated; the
covariance diagonal is std^2 (angles in rad^2), an unobserved roll pi^2/3,
an unobserved velocity 1e4.

Usage: ros2bag_check.py BAG.mcap POSES.jsonl [--namespace NS]
           [--frames BEACON,BASE_LINK,MAP] [--site HEADING_DEG,N,E,D]
Prints `pose=N odom=N tf=N ok=N static=S diag=D`; any mismatch is an
exception (exit 1). With --site the bag must hold one /tf_static (reliable,
transient local): MAP -> BEACON, the beacon at (E, N, -D) in ENU, turned
about up by 90 deg - heading (x of B points at the heading).
"""

import argparse

import json
import math
import sys
from pathlib import Path

from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability, QosReliability
from rosbags.rosbag2.metadata import parse_qos
from ruamel.yaml import YAML
from rosbags.typesys import Stores, get_typestore

BEACON = "lightpose_beacon"
BASE_LINK = "base_link"
MAP = "map"
UNOBSERVED_ANGLE_VAR = math.pi**2 / 3.0
UNOBSERVED_VAR = 1.0e4
QOS = {
    "/lightpose/pose": (QosReliability.BEST_EFFORT, QosDurability.VOLATILE),
    "/lightpose/odom": (QosReliability.BEST_EFFORT, QosDurability.VOLATILE),
    "/tf": (QosReliability.RELIABLE, QosDurability.VOLATILE),
}
TYPES = {
    "/lightpose/pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "/lightpose/odom": "nav_msgs/msg/Odometry",
    "/tf": "tf2_msgs/msg/TFMessage",
}
# Topics a bag may hold beside the poses (the daemon's ROS 2 recordings
# carry each STATUS as /diagnostics): type and QoS checked, messages not
# compared with POSE lines.
OPTIONAL = {
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/tf_static": "tf2_msgs/msg/TFMessage",
}
QOS["/diagnostics"] = (QosReliability.RELIABLE, QosDurability.VOLATILE)
QOS["/tf_static"] = (QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL)
ALL = {**TYPES, **OPTIONAL}


def set_namespace(ns):
    """The pose's and odometry's topics under NS (the module's tables)."""
    ns = ns.rstrip("/")
    for old in ("/lightpose/pose", "/lightpose/odom"):
        new = ns + old[len("/lightpose"):]
        for table in (QOS, TYPES, ALL):
            table[new] = table.pop(old)
    return ns + "/pose", ns + "/odom"


def close(a, b, what):
    if not abs(a - b) <= 1e-9 * max(abs(a), abs(b), 1.0):
        raise AssertionError(f"{what}: {a!r} != {b!r}")


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return [[1, 0, 0], [0, c, -s], [0, s, c]]


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return [[c, 0, s], [0, 1, 0], [-s, 0, c]]


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return [[c, -s, 0], [s, c, 0], [0, 0, 1]]


def quat_matrix(q):
    x, y, z, w = q.x, q.y, q.z, q.w
    n = math.sqrt(x * x + y * y + z * z + w * w)
    close(n, 1.0, "quaternion norm")
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]


def expected_rotation(p):
    pitch, yaw = math.radians(p["pitch"]), math.radians(p["yaw"])
    roll = math.radians(p["roll"]) if p.get("roll") is not None else 0.0
    r0 = [[-1, 0, 0], [0, 1, 0], [0, 0, -1]]
    r_bv = matmul(matmul(matmul(r0, rot_z(yaw)), rot_y(pitch)), rot_x(roll))
    return matmul(r_bv, [[1, 0, 0], [0, -1, 0], [0, 0, -1]])


def stamp_s(p):
    return p["time"] if p.get("time") is not None else p["t"]


def stamp_ns(p):
    # Whole seconds and the fraction apart: t * 1e9 as a float would lose
    # hundreds of ns at Unix times.
    t = stamp_s(p)
    sec = math.floor(t)
    return sec * 1_000_000_000 + round((t - sec) * 1e9)


def check_pose(pose, p, what):
    """A geometry_msgs/Pose (or Transform as position/orientation) against POSE p."""
    pos, q = pose
    for k in "xyz":
        close(getattr(pos, k), p[k], f"{what} {k}")
    want = expected_rotation(p)
    have = quat_matrix(q)
    for i in range(3):
        for j in range(3):
            # Rotation entries are O(1): absolute 1e-9.
            if abs(have[i][j] - want[i][j]) > 1e-9:
                raise AssertionError(f"{what} R[{i}][{j}]: {have[i][j]} != {want[i][j]}")


def check_cov(cov, want_diag, what):
    assert len(cov) == 36, what
    for i in range(6):
        for j in range(6):
            v = float(cov[6 * i + j])
            if i == j:
                if not (math.isfinite(v) and v > 0):
                    raise AssertionError(f"{what}[{i}][{i}] = {v}")
                close(v, want_diag[i], f"{what}[{i}][{i}]")
            elif v != 0.0:
                raise AssertionError(f"{what}[{i}][{j}] = {v}")


def check_header(h, p, frame, what):
    ns = h.stamp.sec * 1_000_000_000 + h.stamp.nanosec
    assert abs(ns - stamp_ns(p)) <= 1, f"{what} stamp {ns} ns for {stamp_s(p)} s"
    assert h.frame_id == frame, f"{what} frame_id {h.frame_id!r}"


def pose_var(p):
    s = p["std"]
    roll = (
        math.radians(s["roll"]) ** 2
        if p.get("roll") is not None and s.get("roll")
        else UNOBSERVED_ANGLE_VAR
    )
    return [
        s["x"] ** 2,
        s["y"] ** 2,
        s["z"] ** 2,
        roll,
        math.radians(s["pitch"]) ** 2,
        math.radians(s["yaw"]) ** 2,
    ]


def check_mcap(bag):
    """The file as the mcap package reads it: profile, encodings, QoS."""
    with open(bag, "rb") as f:
        r = make_reader(f)
        assert r.get_header().profile == "ros2", r.get_header().profile
        summary = r.get_summary()
        schemas = {s.id: s for s in summary.schemas.values()}
        topics = {}
        for c in summary.channels.values():
            s = schemas[c.schema_id]
            assert s.encoding == "ros2msg", (c.topic, s.encoding)
            assert c.message_encoding == "cdr", (c.topic, c.message_encoding)
            (qos,) = parse_qos(c.metadata["offered_qos_profiles"])
            assert (qos.reliability, qos.durability) == QOS[c.topic], (c.topic, qos)
            # Keep last 10 (the node's default); /tf_static's one message, 1.
            assert qos.depth == (1 if c.topic == "/tf_static" else 10), (c.topic, qos)
            assert s.name == ALL[c.topic], (c.topic, s.name)
            assert s.data.decode().count("MSG: std_msgs/msg/Header\n") == 1, s.name
            topics[c.topic] = c.id
        assert set(topics) - set(OPTIONAL) == set(TYPES), topics
        n, total = 0, 0
        pose_channels = {topics[t] for t in TYPES}
        for _, c, m in r.iter_messages():
            assert m.data[:4] == b"\x00\x01\x00\x00", m.data[:4]
            n += c.id in pose_channels
            total += 1
        # rosbag2's own record of the bag: version 8 (numeric QoS), the
        # topics with their counts.
        (meta,) = [m for m in r.iter_metadata() if m.name == "rosbag2"]
        info = YAML(typ="safe").load(meta.metadata["serialized_metadata"])
        assert info["version"] == 8 and info["storage_identifier"] == "mcap", info
        assert info["message_count"] == total, (info["message_count"], total)
        assert info["relative_file_paths"] == [Path(bag).name], info
        for t in info["topics_with_message_count"]:
            tm = t["topic_metadata"]
            assert tm["type"] == ALL[tm["name"]] and tm["serialization_format"] == "cdr", tm
            if tm["name"] in TYPES:
                assert t["message_count"] == n // 3, t
            (qos,) = parse_qos(tm["offered_qos_profiles"])
            assert (qos.reliability, qos.durability) == QOS[tm["name"]], (tm, qos)
        assert len(info["topics_with_message_count"]) == len(topics), info
        return n


def check_static(m, site, frames):
    """The site's transform: MAP -> BEACON, ENU."""
    heading, n, e, d = site
    (tr,) = m.transforms
    assert tr.header.frame_id == frames[2], tr.header.frame_id
    assert tr.child_frame_id == frames[0], tr.child_frame_id
    t, q = tr.transform.translation, tr.transform.rotation
    for have, want, k in ((t.x, e, "x"), (t.y, n, "y"), (t.z, -d, "z")):
        close(have, want, f"/tf_static {k}")
    yaw = math.radians(90.0 - heading)
    want = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    have = (q.x, q.y, q.z, q.w)
    # q and -q are one rotation.
    if not any(all(abs(h - sg * w) <= 1e-9 for h, w in zip(have, want)) for sg in (1, -1)):
        raise AssertionError(f"/tf_static rotation {have} != +-{want}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("bag")
    ap.add_argument("poses")
    ap.add_argument("--namespace", default="/lightpose")
    ap.add_argument("--frames", default=f"{BEACON},{BASE_LINK},{MAP}")
    ap.add_argument("--site", default=None)
    a = ap.parse_args()
    bag, poses_path = Path(a.bag), Path(a.poses)
    pose_topic, odom_topic = set_namespace(a.namespace)
    frames = a.frames.split(",")
    beacon, base_link = frames[0], frames[1]
    site = [float(v) for v in a.site.split(",")] if a.site else None
    poses = {}
    for line in poses_path.read_text().splitlines():
        if line.strip():
            p = json.loads(line)
            if p.get("class") == "POSE" and p.get("status") == "ok":
                poses[(p["seq"])] = p
    by_stamp = {}
    for p in poses.values():
        by_stamp.setdefault(stamp_ns(p), []).append(p)

    raw = check_mcap(bag)
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    counts = {t: 0 for t in TYPES}
    statics, diags = 0, 0
    with AnyReader([bag]) as reader:
        for t in {ALL[c.topic] for c in reader.connections}:
            # The bag's definitions are ROS 2's own: the same type hash.
            have, want = reader.typestore.hash_rihs01(t), jazzy.hash_rihs01(t)
            assert have == want, f"{t}: {have} != {want}"
        optional = [c for c in reader.connections if c.topic in OPTIONAL]
        # (An empty list would read every connection.)
        for conn, ts, data in reader.messages(connections=optional) if optional else []:
            m = reader.deserialize(data, conn.msgtype)
            if conn.topic == "/tf_static":
                assert site, "a /tf_static in a bag made without a site"
                check_static(m, site, frames)
                statics += 1
            else:
                (st,) = m.status
                assert st.name == "lightposed" and st.values, st
                diags += 1
        assert (statics == 1) == (site is not None), f"{statics} /tf_static"
        pose_conns = [c for c in reader.connections if c.topic in TYPES]
        for conn, ts, data in reader.messages(connections=pose_conns):
            m = reader.deserialize(data, conn.msgtype)
            # Rounding to the nanosecond may differ by one between the two.
            ps = next((by_stamp[k] for k in range(ts - 2, ts + 3) if k in by_stamp), None)
            assert ps and len(ps) == 1, f"{conn.topic}: no single ok POSE at log time {ts}"
            p = ps[0]
            what = f"{conn.topic} seq {p['seq']}"
            if conn.topic == pose_topic:
                check_header(m.header, p, beacon, what)
                check_pose((m.pose.pose.position, m.pose.pose.orientation), p, what)
                check_cov(m.pose.covariance, pose_var(p), what + " covariance")
            elif conn.topic == odom_topic:
                check_header(m.header, p, beacon, what)
                assert m.child_frame_id == base_link, m.child_frame_id
                check_pose((m.pose.pose.position, m.pose.pose.orientation), p, what)
                check_cov(m.pose.covariance, pose_var(p), what + " covariance")
                surge = p.get("surge")
                close(m.twist.twist.linear.x, surge if surge is not None else 0.0, what + " surge")
                sv = p["std"].get("surge")
                tv = [sv**2 if surge is not None and sv else UNOBSERVED_VAR] + [UNOBSERVED_VAR] * 5
                check_cov(m.twist.covariance, tv, what + " twist covariance")
            else:
                assert len(m.transforms) == 1, what
                tr = m.transforms[0]
                check_header(tr.header, p, beacon, what)
                assert tr.child_frame_id == base_link, tr.child_frame_id
                check_pose((tr.transform.translation, tr.transform.rotation), p, what)
            counts[conn.topic] += 1
    for topic, n in counts.items():
        assert n == len(poses), f"{topic}: {n} messages for {len(poses)} ok POSE lines"
    assert raw == 3 * len(poses), (raw, len(poses))
    print(
        f"pose={counts[pose_topic]} odom={counts[odom_topic]} "
        f"tf={counts['/tf']} ok={len(poses)} static={statics} diag={diags}"
    )


if __name__ == "__main__":
    main()
