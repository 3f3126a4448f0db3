"""An independent Foxglove WebSocket client (Python `websockets`, pinned in
tests/python/requirements.txt), speaking the protocol by hand, for
tests/live.rs:

    python foxglove_client.py ws://HOST:PORT FRAMES

Offers subprotocol foxglove.websocket.v1, reads serverInfo and advertise,
checks that every channel of a lightpose recording is advertised with its
JSON Schema, subscribes to frame, pose, image, vehicle pose, transform and
status, and decodes binary messageData frames (opcode 1, subscription id
u32 LE, log time u64 LE, JSON) until it has FRAMES frames with their
images and poses. Each frame is checked (25 counts, log time = its t in
ns), each image against its frame's counts. Prints one JSON object: the
frames and poses as received (text, by seq), the other channels' counts,
the binary messages received in all and the subprotocol. Any mismatch: one line on stderr, exit 1.
"""

import asyncio
import base64
import json
import struct
import sys

from websockets.asyncio.client import connect

WANT = {
    "/lightpose/frame": "lightpose.Frame",
    "/lightpose/pose": "lightpose.Pose",
    "/lightpose/status": "lightpose.Status",
    "/lightpose/image": "foxglove.RawImage",
    "/lightpose/vehicle_pose": "foxglove.PoseInFrame",
    "/lightpose/truth_pose": "foxglove.PoseInFrame",
    "/lightpose/tf": "foxglove.FrameTransform",
}
SUBSCRIBE = ["/lightpose/frame", "/lightpose/pose", "/lightpose/image",
             "/lightpose/vehicle_pose", "/lightpose/tf", "/lightpose/status"]


def fail(msg):
    print(f"foxglove_client: {msg}", file=sys.stderr)
    sys.exit(1)


def check_advertise(adv):
    if adv.get("op") != "advertise":
        fail(f"second message is {adv.get('op')}, not advertise")
    found = {}
    for ch in adv["channels"]:
        if ch["encoding"] != "json" or ch.get("schemaEncoding") != "jsonschema":
            fail(f"{ch['topic']}: {ch['encoding']} / {ch.get('schemaEncoding')}")
        if json.loads(ch["schema"])["title"] != ch["schemaName"]:
            fail(f"{ch['topic']}: schema title is not {ch['schemaName']}")
        found[ch["topic"]] = ch["schemaName"]
    if found != WANT:
        fail(f"advertised {found}")
    return {ch["topic"]: ch["id"] for ch in adv["channels"]}


def check_frame(data, log_time):
    if data.get("class") != "FRAME" or len(data.get("counts", [])) != 25:
        fail(f"not a FRAME of 25 counts: {data}")
    if abs(log_time - data["t"] * 1e9) > 1.0:
        fail(f"frame {data['seq']}: log time {log_time} for t = {data['t']}")


async def run(url, want):
    async with connect(url, subprotocols=["foxglove.websocket.v1"], max_size=None) as ws:
        if ws.subprotocol != "foxglove.websocket.v1":
            fail(f"subprotocol {ws.subprotocol}")
        info = json.loads(await ws.recv())
        if info.get("op") != "serverInfo" or not info.get("name", "").startswith("lightposed"):
            fail(f"first message is not lightposed's serverInfo: {info}")
        ids = check_advertise(json.loads(await ws.recv()))
        subs = [{"id": 100 + i, "channelId": ids[t]} for i, t in enumerate(SUBSCRIBE)]
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        topic_of = {s["id"]: SUBSCRIBE[i] for i, s in enumerate(subs)}
        frames, poses, images, other = {}, {}, {}, {}
        received = 0
        def incomplete():
            return any(lt not in images or s not in poses for s, (_, lt) in frames.items())

        while len(frames) < want or incomplete():
            msg = await asyncio.wait_for(ws.recv(), 20)
            if isinstance(msg, str):
                continue  # a status or other text message
            if msg[0] != 1 or len(msg) < 13:
                fail(f"binary message with opcode {msg[0]}, {len(msg)} bytes")
            received += 1
            sub, log_time = struct.unpack_from("<IQ", msg, 1)
            topic = topic_of.get(sub) or fail(f"subscription id {sub} never asked for")
            text = msg[13:].decode()
            data = json.loads(text)
            if topic == "/lightpose/frame":
                check_frame(data, log_time)
                if len(frames) < want:
                    frames[data["seq"]] = (text, log_time)
            elif topic == "/lightpose/pose":
                poses[data["seq"]] = text
            elif topic == "/lightpose/image":
                counts = list(struct.unpack("<25H", base64.b64decode(data["data"])))
                images[log_time] = counts
            else:
                other[topic] = other.get(topic, 0) + 1
        by_time = {lt: seq for seq, (_, lt) in frames.items()}
        for lt, seq in by_time.items():
            if images.get(lt) != json.loads(frames[seq][0])["counts"]:
                fail(f"image of frame {seq} is not its counts")
        print(json.dumps({
            "subprotocol": ws.subprotocol,
            "frames": {s: f for s, (f, _) in frames.items()},
            "poses": {s: p for s, p in poses.items() if s in frames},
            "other": other,
            "received": received,
        }))


if __name__ == "__main__":
    if len(sys.argv) != 3:
        fail("usage: foxglove_client.py ws://HOST:PORT FRAMES")
    asyncio.run(run(sys.argv[1], int(sys.argv[2])))
