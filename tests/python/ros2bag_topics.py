"""Count a ROS 2 bag's messages per topic with rosbags (types from the
bag's own schemas), deserializing each, and print `topic=N` lines sorted,
then the levels seen on /diagnostics as `diagnostics_levels=a,b`.

Usage: ros2bag_topics.py BAG.mcap
"""

import sys
from pathlib import Path

from rosbags.highlevel import AnyReader

counts = {}
levels = set()
with AnyReader([Path(sys.argv[1])]) as reader:
    for conn, _t, raw in reader.messages():
        msg = reader.deserialize(raw, conn.msgtype)
        counts[conn.topic] = counts.get(conn.topic, 0) + 1
        if conn.topic == "/diagnostics":
            for s in msg.status:
                levels.add(int.from_bytes(s.level, "little") if isinstance(s.level, bytes) else int(s.level))
for topic in sorted(counts):
    print(f"{topic}={counts[topic]}")
print("diagnostics_levels=" + ",".join(str(x) for x in sorted(levels)))
