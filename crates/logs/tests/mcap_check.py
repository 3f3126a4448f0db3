"""Independent check of a lightpose MCAP with the reference Python `mcap`
library (pinned in tests/python/requirements.txt), run by tests/python.rs.

    python mcap_check.py full REC.mcap LOG.jsonl [POSES.jsonl]
    python mcap_check.py cut PREFIX.mcap

`full`: the MCAP's summary, metadata and every message against the JSONL
log (and POSE lines) it must hold, JSON parsed by Python's own json module
and every float compared bit for bit; the Foxglove channels decoded and
checked against the frames and poses (the attitude quaternion against
MODEL.md's forward axis); `lightpose-clock` records, if any, checked and
counted (`clock=N` at the end). Prints one line of counts.

`cut`: a file cut short, read by the library's non-seeking reader, which
yields what it can before the cut; prints the number of FRAME messages.

    python mcap_check.py default FILE.mcap
    python mcap_check.py alike A.mcap B.mcap

`default`: the library's default reader as a user opens a file
(`make_reader` on a seekable file: the seeking reader, through the
summary), every message in log-time order, then the metadata and
attachments: one line of counts (messages, per topic, metadata,
`lightpose-clock` records, attachments), or `error=CLASS` when the reader
fails (a file cut short). `alike`: two finished files hold the same
messages on every topic (channel declaration, sequence, times and bytes)
and the same metadata records in the same order.

    python mcap_check.py v3 REC.mcap BURST_LOG.jsonl POSES.jsonl

`v3` (spec v3): a recording of BURST frames. Each `/lightpose/burst`
message is decoded from its layout (lightpose.Burst v1: the schema data)
by this script's own reading of it, its line rebuilt and compared with the
JSONL line byte for byte, its samples with the line's; each image is the
rounded mean of its burst's channels; truths and poses (with their roll)
against MODEL.md's full R_BV = R0·Rz(ψ)·Ry(θ)·Rx(φ), every axis. Prints
one line of counts, `rolled=N` the poses with a roll.

Any mismatch: one line on stderr, exit 1.
"""

import base64
import json
import math
import struct
import sys

from mcap.reader import NonSeekingReader, make_reader

EXPECTED = {
    "/lightpose/frame": "lightpose.Frame",
    "/lightpose/pose": "lightpose.Pose",
    "/lightpose/status": "lightpose.Status",
    "/lightpose/image": "foxglove.RawImage",
    "/lightpose/vehicle_pose": "foxglove.PoseInFrame",
    "/lightpose/truth_pose": "foxglove.PoseInFrame",
    "/lightpose/tf": "foxglove.FrameTransform",
}


def fail(msg):
    print(f"mcap_check: {msg}", file=sys.stderr)
    sys.exit(1)


def same(a, b, where):
    """Equal JSON values, floats bit for bit."""
    if isinstance(a, float) or isinstance(b, float):
        if not (isinstance(a, float) and isinstance(b, float)):
            fail(f"{where}: {a!r} vs {b!r}")
        if struct.pack("<d", a) != struct.pack("<d", b):
            fail(f"{where}: {a!r} vs {b!r} differ in bits")
    elif isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            fail(f"{where}: keys {sorted(a)} vs {sorted(b)}")
        for k in a:
            same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            fail(f"{where}: {len(a)} vs {len(b)} items")
        for i, (x, y) in enumerate(zip(a, b)):
            same(x, y, f"{where}[{i}]")
    elif type(a) is not type(b) or a != b:
        fail(f"{where}: {a!r} vs {b!r}")


def stamp_ns(ts):
    return ts["sec"] * 1_000_000_000 + ts["nsec"]


def rotate(q, v):
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    u = (x, y, z)

    def cross(a, b):
        return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])

    t = cross(u, v)
    tt = cross(u, t)
    return tuple(v[i] + 2 * w * t[i] + 2 * tt[i] for i in range(3))


def check_pose(pose, x, y, z, pitch, yaw, where):
    p, q = pose["position"], pose["orientation"]
    same([p["x"], p["y"], p["z"]], [float(x), float(y), float(z)], f"{where} position")
    if abs(math.sqrt(sum(q[k] ** 2 for k in "xyzw")) - 1) > 1e-12:
        fail(f"{where}: quaternion is not a unit")
    th, ps = math.radians(pitch), math.radians(yaw)
    # MODEL.md: the forward axis in B is (−cθ·cψ, cθ·sψ, sθ).
    want = (-math.cos(th) * math.cos(ps), math.cos(th) * math.sin(ps), math.sin(th))
    got = rotate(q, (1.0, 0.0, 0.0))
    if max(abs(a - b) for a, b in zip(got, want)) > 1e-12:
        fail(f"{where}: the bow points {got}, MODEL.md says {want}")


def r_bv(pitch, yaw, roll):
    """MODEL.md's R_BV as three columns (the body's x, y, z axes in B)."""
    th, ps, ph = math.radians(pitch), math.radians(yaw), math.radians(roll)

    def mul(a, b):
        return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]

    r0 = [[-1, 0, 0], [0, 1, 0], [0, 0, -1]]
    rz = [[math.cos(ps), -math.sin(ps), 0], [math.sin(ps), math.cos(ps), 0], [0, 0, 1]]
    ry = [[math.cos(th), 0, math.sin(th)], [0, 1, 0], [-math.sin(th), 0, math.cos(th)]]
    rx = [[1, 0, 0], [0, math.cos(ph), -math.sin(ph)], [0, math.sin(ph), math.cos(ph)]]
    m = mul(mul(mul(r0, rz), ry), rx)
    return [tuple(m[i][j] for i in range(3)) for j in range(3)]


def check_rolled_pose(pose, want, where):
    """A PoseInFrame's pose against x, y, z, pitch, yaw, roll (degrees)."""
    x, y, z, pitch, yaw, roll = want
    p, q = pose["position"], pose["orientation"]
    same([p["x"], p["y"], p["z"]], [float(x), float(y), float(z)], f"{where} position")
    for axis, col in enumerate(r_bv(pitch, yaw, roll)):
        e = tuple(1.0 if i == axis else 0.0 for i in range(3))
        got = rotate(q, e)
        if max(abs(a - b) for a, b in zip(got, col)) > 1e-12:
            fail(f"{where}: body axis {axis} is {got} in B, MODEL.md says {col}")


LAYOUT = struct.Struct("<4sQdHHBBII")


def burst_line(data, where):
    """The BURST line of a /lightpose/burst message, and its samples."""
    magic, seq, t, channels, n, adc_bits, cut, at, side_len = LAYOUT.unpack_from(data)
    if magic != b"LPB1" or channels != 25:
        fail(f"{where}: magic {magic!r}, {channels} channels")
    side = data[LAYOUT.size:LAYOUT.size + side_len]
    raw = data[LAYOUT.size + side_len:]
    if len(raw) != 2 * channels * n:
        fail(f"{where}: {len(raw)} bytes of samples for {channels} x {n}")
    flat = struct.unpack(f"<{channels * n}H", raw)
    samples = [list(flat[k * n:(k + 1) * n]) for k in range(channels)]
    text = '"samples":' + json.dumps(samples, separators=(",", ":"))
    text = text.encode()
    if cut == 0:
        line = side[:at] + text + b"," + side[at:]
    elif cut == 1:
        line = side[:at] + b"," + text + side[at:]
    elif cut == 2:
        line = side
    else:
        fail(f"{where}: cut {cut}")
    if cut != 2:
        obj = json.loads(side)
        if obj.get("seq") != seq or "samples" in obj:
            fail(f"{where}: side {obj}")
    return line.decode(), samples, seq, t, adc_bits


def v3(path, log, poses_path):
    with open(log, encoding="utf-8") as f:
        lines = [line.rstrip("\n") for line in f if line.strip()]
    bursts = [json.loads(line) for line in lines[1:]]
    poses = read_lines(poses_path)
    topics = ["/lightpose/burst", "/lightpose/pose", "/lightpose/image", "/lightpose/vehicle_pose", "/lightpose/truth_pose", "/lightpose/tf"]
    n = {t: 0 for t in topics}
    rolled = 0
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None:
            fail("no summary")
        for ch in summary.channels.values():
            if ch.topic == "/lightpose/burst":
                schema = summary.schemas[ch.schema_id]
                if (schema.name, schema.encoding, ch.message_encoding) != ("lightpose.Burst", "lightpose-layout", "lightpose-burst-v1"):
                    fail(f"burst channel: {schema.name} {schema.encoding} {ch.message_encoding}")
                if not schema.data.startswith(b"lightpose.Burst v1"):
                    fail("burst schema data is not its layout")
        for _schema, ch, msg in reader.iter_messages(log_time_order=False):
            if ch.topic not in n:
                continue
            i = n[ch.topic]
            n[ch.topic] += 1
            where = f"{ch.topic} #{i}"
            if ch.topic == "/lightpose/burst":
                line, samples, seq, t, adc_bits = burst_line(msg.data, where)
                if line != lines[1 + i]:
                    fail(f"{where}: the rebuilt line is not the JSONL line")
                b = bursts[i]
                if samples != b["samples"] or seq != b["seq"] or t != b["t"] or adc_bits != 12:
                    fail(f"{where}: fields")
                if abs(msg.log_time - t * 1e9) > 1.0:
                    fail(f"{where}: log time {msg.log_time} for t = {t}")
                continue
            data = json.loads(msg.data)
            if ch.topic == "/lightpose/image":
                counts = list(struct.unpack("<25H", base64.b64decode(data["data"])))
                s = bursts[i]["samples"]
                want = [int((sum(c) + len(c) // 2) // len(c)) for c in s]
                if counts != want:
                    fail(f"{where}: pixels {counts} vs means {want}")
            elif ch.topic == "/lightpose/truth_pose":
                tr = bursts[i]["truth"]
                check_rolled_pose(data["pose"], [tr[k] for k in ("x", "y", "z", "pitch", "yaw")] + [tr.get("roll", 0.0)], where)
            elif ch.topic == "/lightpose/pose":
                same(data, poses[i], where)
                rolled += "roll" in data
            else:
                p = poses[i]
                want = [p[k] for k in ("x", "y", "z", "pitch", "yaw")] + [p.get("roll", 0.0)]
                pose = data["pose"] if ch.topic == "/lightpose/vehicle_pose" else {"position": data["translation"], "orientation": data["rotation"]}
                check_rolled_pose(pose, want, where)
    if n["/lightpose/burst"] != len(bursts):
        fail(f"{n['/lightpose/burst']} bursts for {len(bursts)} lines")
    counts = [f"{t.split('/')[-1]}={c}" for t, c in n.items()]
    print(" ".join(counts) + f" rolled={rolled}")


def read_lines(path):
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]


def check_summary(reader, header_line):
    summary = reader.get_summary()
    if summary is None:
        fail("no summary (the file was not finished)")
    found = {}
    for ch in summary.channels.values():
        schema = summary.schemas[ch.schema_id]
        if ch.message_encoding != "json" or schema.encoding != "jsonschema":
            fail(f"{ch.topic}: {ch.message_encoding} messages, {schema.encoding} schema")
        if json.loads(schema.data)["title"] != schema.name:
            fail(f"{ch.topic}: schema title is not {schema.name}")
        found[ch.topic] = schema.name
    if found != EXPECTED:
        fail(f"channels {found}")
    metas = [m for m in reader.iter_metadata() if m.name == "lightpose-header"]
    if len(metas) != 1 or metas[0].metadata.get("json") != header_line:
        fail("lightpose-header metadata is not the HEADER line")
    return summary


def check_clocks(reader):
    """The `lightpose-clock` records (a daemon's recording): their count."""
    n = 0
    for m in reader.iter_metadata():
        if m.name != "lightpose-clock":
            continue
        c, where = m.metadata, f"lightpose-clock #{n}"
        n += 1
        if c.get("epoch") not in ("monotonic", "source"):
            fail(f"{where}: epoch {c.get('epoch')!r}")
        if c.get("synced") not in ("true", "false", "unknown"):
            fail(f"{where}: synced {c.get('synced')!r}")
        if c.get("reason") not in ("open", "step", "sync") or (n == 1) != (c["reason"] == "open"):
            fail(f"{where}: reason {c.get('reason')!r}")
        try:
            t, unix, offset = float(c["t"]), float(c["unix"]), float(c["offset"])
        except (KeyError, ValueError) as e:
            fail(f"{where}: {e!r} in {c}")
        if abs(offset - (unix - t)) > 1e-6:
            fail(f"{where}: offset {offset} is not unix - t")
        if "log_time" in c and abs(int(c["log_time"]) - t * 1e9) > max(1.0, t * 1e-6):
            fail(f"{where}: log_time {c['log_time']} for t = {t}")
    return n


def full(path, log, poses_path):
    with open(log, encoding="utf-8") as f:
        lines = [line.rstrip("\n") for line in f if line.strip()]
    frames = [json.loads(line) for line in lines[1:]]
    poses = read_lines(poses_path) if poses_path else None
    n = {topic: 0 for topic in EXPECTED}
    with open(path, "rb") as f:
        reader = make_reader(f)
        check_summary(reader, lines[0])
        clocks = check_clocks(reader)
        for _schema, ch, msg in reader.iter_messages(log_time_order=False):
            i = n[ch.topic]
            n[ch.topic] += 1
            data = json.loads(msg.data)
            where = f"{ch.topic} #{i}"
            if msg.publish_time != msg.log_time:
                fail(f"{where}: publish time {msg.publish_time} != log time {msg.log_time}")
            if ch.topic == "/lightpose/frame":
                same(data, frames[i], where)
                t_ns = frames[i]["t"] * 1e9
                if abs(msg.log_time - t_ns) > max(1.0, t_ns * 1e-15):
                    fail(f"{where}: log time {msg.log_time} for t = {frames[i]['t']}")
            elif ch.topic == "/lightpose/image":
                f_ = frames[i]
                if (data["width"], data["height"], data["step"], data["encoding"]) != (5, 5, 10, "mono16"):
                    fail(f"{where}: {data['width']}x{data['height']} {data['encoding']}")
                counts = list(struct.unpack("<25H", base64.b64decode(data["data"])))
                if counts != f_["counts"]:
                    fail(f"{where}: pixels {counts} vs counts {f_['counts']}")
                if stamp_ns(data["timestamp"]) != msg.log_time:
                    fail(f"{where}: timestamp")
            elif ch.topic == "/lightpose/truth_pose":
                tr = [f_ for f_ in frames if "truth" in f_][i]["truth"]
                check_pose(data["pose"], tr["x"], tr["y"], tr["z"], tr["pitch"], tr["yaw"], where)
            elif ch.topic == "/lightpose/pose":
                if poses is not None:
                    same(data, poses[i], where)
            elif ch.topic in ("/lightpose/vehicle_pose", "/lightpose/tf"):
                if poses is not None:
                    known = [p for p in poses if all(p.get(k) is not None for k in ("x", "y", "z", "pitch", "yaw"))]
                    p = known[i]
                    if ch.topic == "/lightpose/tf":
                        if (data["parent_frame_id"], data["child_frame_id"]) != ("beacon", "vehicle"):
                            fail(f"{where}: {data['parent_frame_id']} -> {data['child_frame_id']}")
                        pose = {"position": data["translation"], "orientation": data["rotation"]}
                    else:
                        if data["frame_id"] != "beacon":
                            fail(f"{where}: frame {data['frame_id']}")
                        pose = data["pose"]
                    check_pose(pose, p["x"], p["y"], p["z"], p["pitch"], p["yaw"], where)
            elif ch.topic == "/lightpose/status":
                if data.get("class") != "STATUS":
                    fail(f"{where}: class {data.get('class')}")
    if n["/lightpose/frame"] != len(frames) or n["/lightpose/image"] != len(frames):
        fail(f"{n['/lightpose/frame']} frames and {n['/lightpose/image']} images for {len(frames)} lines")
    if poses is not None and n["/lightpose/pose"] != len(poses):
        fail(f"{n['/lightpose/pose']} poses for {len(poses)} lines")
    counts = [f"{t.split('/')[-1]}={c}" for t, c in n.items()]
    if clocks:
        counts.append(f"clock={clocks}")
    print(" ".join(counts))


def cut(path):
    frames = 0
    with open(path, "rb") as f:
        try:
            for _schema, ch, _msg in NonSeekingReader(f).iter_messages(log_time_order=False):
                frames += ch.topic == "/lightpose/frame"
        except Exception:  # the cut: what came before it counts
            pass
    print(f"frames={frames}")


def default(path):
    n = {}
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            for _schema, ch, _msg in reader.iter_messages():
                n[ch.topic] = n.get(ch.topic, 0) + 1
            summary = reader.get_summary()
            metas = [m.name for m in reader.iter_metadata()]
            attachments = sum(1 for _ in reader.iter_attachments())
    except Exception as e:  # what a user of the library meets
        print(f"error={type(e).__name__}")
        return
    total = sum(n.values())
    if summary is None:
        fail("no summary")
    if summary.statistics is not None and summary.statistics.message_count != total:
        fail(f"statistics say {summary.statistics.message_count} messages, {total} read")
    counts = [f"messages={total}"] + [f"{t.split('/')[-1]}={c}" for t, c in sorted(n.items())]
    counts += [f"metadata={len(metas)}", f"clock={metas.count('lightpose-clock')}", f"attachments={attachments}"]
    print(" ".join(counts))


def dump(path):
    msgs = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, ch, m in reader.iter_messages(log_time_order=False):
            decl = (schema.name, schema.encoding, schema.data) if schema else None
            key = (ch.topic, ch.message_encoding, tuple(sorted(ch.metadata.items())), decl)
            msgs.setdefault(key, []).append((m.sequence, m.log_time, m.publish_time, bytes(m.data)))
        metas = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
    return msgs, metas


def alike(a, b):
    (ma, ta), (mb, tb) = dump(a), dump(b)
    for key in sorted(set(ma) | set(mb), key=repr):
        x, y = ma.get(key, []), mb.get(key, [])
        if x != y:
            i = next((i for i, (p, q) in enumerate(zip(x, y)) if p != q), min(len(x), len(y)))
            fail(f"{key[0]} ({key[3][0] if key[3] else 'no schema'}): {len(x)} vs {len(y)} messages, first difference at #{i}")
    if ta != tb:
        fail(f"metadata {[m[0] for m in ta]} vs {[m[0] for m in tb]}")
    print(f"messages={sum(len(v) for v in ma.values())} metadata={len(ta)}")


if __name__ == "__main__":
    if len(sys.argv) >= 4 and sys.argv[1] == "full":
        full(sys.argv[2], sys.argv[3], sys.argv[4] if len(sys.argv) > 4 else None)
    elif len(sys.argv) == 5 and sys.argv[1] == "v3":
        v3(sys.argv[2], sys.argv[3], sys.argv[4])
    elif len(sys.argv) == 3 and sys.argv[1] == "cut":
        cut(sys.argv[2])
    elif len(sys.argv) == 3 and sys.argv[1] == "default":
        default(sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "alike":
        alike(sys.argv[2], sys.argv[3])
    else:
        fail("usage: mcap_check.py full REC.mcap LOG.jsonl [POSES.jsonl] | cut PREFIX.mcap | default FILE.mcap | alike A.mcap B.mcap")
