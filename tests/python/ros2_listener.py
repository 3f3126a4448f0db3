"""A ROS 2 participant of another DDS (Eclipse Cyclone DDS, the one under
rmw_cyclonedds), with ROS 2's own DDS type and topic names, listening to
lightposed's node: what a ROS 2 node would receive, without a ROS install.

Usage: ros2_listener.py SECONDS [DOMAIN] [NAMESPACE]
Listens for SECONDS from the first pose heard (at most 20 s more for it).
Prints one JSON object per received sample on stdout:
  {"topic": "pose"|"odom"|"tf"|"tf_static"|"diagnostics", "stamp": unix s,
   "xyz": [..], "q": [x, y, z, w], "cov": [36 floats], ...}
and a last line {"done": true, "counts": {...}}. It also reads the ROS 2
graph's `ros_discovery_info` (what `ros2 node list` reads), its GID as
the distro has it: GID_BYTES=16 (Iron, Jazzy and later; the default) or
24 (Humble), printing {"topic": "graph", "gid_len": n, "nodes": [[ns,
name], ...]} per sample that decodes.
"""

import json
import os
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Qos, Policy
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: array[float64, 36]


@dataclass
class PoseWithCovarianceStamped(
    IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
):
    header: Header
    pose: PoseWithCovariance


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist
    covariance: array[float64, 36]


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str
    value: str


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8
    name: str
    message: str
    hardware_id: str
    values: sequence[KeyValue]


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header
    status: sequence[DiagnosticStatus]


@dataclass
class Imu(IdlStruct, typename="sensor_msgs::msg::dds_::Imu_"):
    header: Header
    orientation: Quaternion
    orientation_covariance: array[float64, 9]
    angular_velocity: Vector3
    angular_velocity_covariance: array[float64, 9]
    linear_acceleration: Vector3
    linear_acceleration_covariance: array[float64, 9]


GID_BYTES = int(os.environ.get("GID_BYTES", "16"))


@dataclass
class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    data: array[uint8, GID_BYTES]


@dataclass
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    node_namespace: str
    node_name: str
    reader_gid_seq: sequence[Gid]
    writer_gid_seq: sequence[Gid]


@dataclass
class ParticipantEntitiesInfo(
    IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
):
    gid: Gid
    node_entities_info_seq: sequence[NodeEntitiesInfo]


def stamp(h):
    return h.stamp.sec + h.stamp.nanosec * 1e-9


def main():
    seconds = float(sys.argv[1])
    domain = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    ns = sys.argv[3] if len(sys.argv) > 3 else "/lightpose"
    dp = DomainParticipant(domain)
    best_effort = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(100))
    reliable = Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(100)
    )
    latched = Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)),
        Policy.Durability.TransientLocal,
        Policy.History.KeepLast(1),
    )
    readers = {
        "pose": DataReader(dp, Topic(dp, f"rt{ns}/pose", PoseWithCovarianceStamped), qos=best_effort),
        "odom": DataReader(dp, Topic(dp, f"rt{ns}/odom", Odometry), qos=best_effort),
        "tf": DataReader(dp, Topic(dp, "rt/tf", TFMessage), qos=reliable),
        "tf_static": DataReader(dp, Topic(dp, "rt/tf_static", TFMessage), qos=latched),
        "diagnostics": DataReader(dp, Topic(dp, "rt/diagnostics", DiagnosticArray), qos=reliable),
        # rmw's own: reliable, transient local, keep last 1.
        "graph": DataReader(dp, Topic(dp, "ros_discovery_info", ParticipantEntitiesInfo), qos=latched),
    }
    counts = {k: 0 for k in readers}
    # The window opens at the first pose heard (discovery takes its time),
    # and the wait for it is bounded.
    end = time.monotonic() + seconds + 20.0
    opened = False
    out = sys.stdout
    while time.monotonic() < end:
        if not opened and counts["pose"] > 0:
            opened = True
            end = time.monotonic() + seconds
        for name, r in readers.items():
            for s in r.take(N=100):
                kinds = (PoseWithCovarianceStamped, Odometry, TFMessage, DiagnosticArray, ParticipantEntitiesInfo)
                if not isinstance(s, kinds):
                    continue  # an invalid sample (a dispose), no data
                counts[name] += 1
                rec = {"topic": name}
                if name == "pose":
                    p = s.pose.pose
                    rec.update(
                        stamp=stamp(s.header),
                        frame_id=s.header.frame_id,
                        xyz=[p.position.x, p.position.y, p.position.z],
                        q=[p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w],
                        cov=list(s.pose.covariance),
                    )
                elif name == "odom":
                    rec.update(
                        stamp=stamp(s.header),
                        frame_id=s.header.frame_id,
                        child=s.child_frame_id,
                        xyz=[s.pose.pose.position.x, s.pose.pose.position.y, s.pose.pose.position.z],
                        surge=s.twist.twist.linear.x,
                        cov=list(s.pose.covariance),
                        twist_cov=list(s.twist.covariance),
                    )
                elif name in ("tf", "tf_static"):
                    t = s.transforms[0]
                    tr = t.transform.translation
                    rec.update(
                        stamp=stamp(t.header),
                        frame_id=t.header.frame_id,
                        child=t.child_frame_id,
                        xyz=[tr.x, tr.y, tr.z],
                    )
                elif name == "graph":
                    rec.update(
                        gid_len=len(s.gid.data),
                        nodes=[[n.node_namespace, n.node_name] for n in s.node_entities_info_seq],
                    )
                else:
                    st = s.status[0]
                    rec.update(level=st.level, name=st.name, message=st.message, values=len(st.values))
                out.write(json.dumps(rec) + "\n")
        out.flush()
        time.sleep(0.01)
    out.write(json.dumps({"done": True, "counts": counts}) + "\n")
    out.flush()


if __name__ == "__main__":
    main()
