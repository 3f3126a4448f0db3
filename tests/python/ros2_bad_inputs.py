"""Feeds lightposed's ROS 2 inputs with Cyclone DDS as drivers on
rmw_cyclonedds would, good readings and bad ones:

- rt/imu/data (sensor_msgs/msg/Imu), rt/depth/pressure
  (sensor_msgs/msg/FluidPressure) and rt/dvl/twist
  (geometry_msgs/msg/TwistWithCovarianceStamped) at 20 Hz for SECONDS;
- then the bad ones, once each kind (counts in the last line):
  Imu: 2 NaN quaternions, 2 of norm 1.2; 3 samples of a shorter type
  registered under the Imu's DDS type name (DDS matches, the reader cannot
  deserialize them); 1 Imu whose frame_id is 1 MB; 3 samples of
  std_msgs/msg/String on rt/imu/data (another type name: no match);
  FluidPressure: a NaN, a negative variance, 2000 m deep;
  Twist: a NaN, 10 m/s;
- then good ones again for 2 s.

Usage: ros2_bad_inputs.py SECONDS
Prints {"good": N, "bad_from": unix s, "bad_to": unix s, "sent": {...}}.
"""

import json
import math
import sys
import time
from dataclasses import dataclass

from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float64
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic

from ros2_listener import Header, Imu, Quaternion, Time, Twist, TwistWithCovariance, Vector3


@dataclass
class FluidPressure(IdlStruct, typename="sensor_msgs::msg::dds_::FluidPressure_"):
    header: Header
    fluid_pressure: float64
    variance: float64


@dataclass
class TwistWithCovarianceStamped(
    IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovarianceStamped_"
):
    header: Header
    twist: TwistWithCovariance


@dataclass
class ShortImu(IdlStruct, typename="sensor_msgs::msg::dds_::Imu_"):
    """Not an Imu: a header alone, under the Imu's type name."""

    header: Header


@dataclass
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


RHO_G = 1025.0 * 9.80665
SURFACE = 101325.0


def header(frame_id="base_link"):
    now = time.time()
    return Header(stamp=Time(sec=int(now), nanosec=int((now % 1) * 1e9)), frame_id=frame_id)


def imu(q, frame_id="imu_link"):
    return Imu(
        header=header(frame_id),
        orientation=q,
        orientation_covariance=[0.0] * 9,
        angular_velocity=Vector3(0.0, 0.0, 0.0),
        angular_velocity_covariance=[0.0] * 9,
        linear_acceleration=Vector3(0.0, 0.0, 9.81),
        linear_acceleration_covariance=[0.0] * 9,
    )


def pressure(p, var=0.0):
    return FluidPressure(header=header("pressure_link"), fluid_pressure=p, variance=var)


def twist(vx, var=0.0001):
    cov = [0.0] * 36
    cov[0] = cov[7] = cov[14] = var
    return TwistWithCovarianceStamped(
        header=header("dvl_link"),
        twist=TwistWithCovariance(
            twist=Twist(linear=Vector3(vx, 0.0, 0.0), angular=Vector3(0.0, 0.0, 0.0)), covariance=cov
        ),
    )


def main():
    seconds = float(sys.argv[1])
    dp = DomainParticipant(0)
    # Other participants for the other types on the Imu's topic name: one
    # participant keeps one type per topic.
    dp_short, dp_wrong = DomainParticipant(0), DomainParticipant(0)
    w_imu = DataWriter(dp, Topic(dp, "rt/imu/data", Imu))
    w_depth = DataWriter(dp, Topic(dp, "rt/depth/pressure", FluidPressure))
    w_dvl = DataWriter(dp, Topic(dp, "rt/dvl/twist", TwistWithCovarianceStamped))
    w_short = DataWriter(dp_short, Topic(dp_short, "rt/imu/data", ShortImu))
    w_wrong = DataWriter(dp_wrong, Topic(dp_wrong, "rt/imu/data", String))
    # Heading 210° (NED) is ENU yaw 90° − 210° = −120°, level.
    yaw = math.radians(90.0 - 210.0)
    good_q = Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    good_p = SURFACE + 2.0 * RHO_G  # 2 m deep
    n_good = 0

    def good_for(s):
        nonlocal n_good
        end = time.monotonic() + s
        while time.monotonic() < end:
            w_imu.write(imu(good_q))
            w_depth.write(pressure(good_p, (0.01 * RHO_G) ** 2))
            w_dvl.write(twist(0.3))
            n_good += 1
            time.sleep(0.05)

    good_for(seconds)
    bad_from = time.time()
    sent = {"imu_angle": 0, "imu_short": 0, "imu_oversized": 0, "imu_wrong_type": 0}
    for q in [
        Quaternion(float("nan"), 0.0, 0.0, 1.0),
        Quaternion(0.0, 0.0, 0.0, 1.2),
        Quaternion(0.0, float("nan"), 0.0, 1.0),
        Quaternion(0.0, 0.0, 1.2, 0.0),
    ]:
        w_imu.write(imu(q))
        sent["imu_angle"] += 1
        time.sleep(0.05)
    for _ in range(3):
        w_short.write(ShortImu(header=header("short")))
        sent["imu_short"] += 1
        time.sleep(0.05)
    w_imu.write(imu(good_q, frame_id="x" * (1 << 20)))
    sent["imu_oversized"] += 1
    time.sleep(0.05)
    for _ in range(3):
        w_wrong.write(String(data="not an imu"))
        sent["imu_wrong_type"] += 1
        time.sleep(0.05)
    for m in [pressure(float("nan")), pressure(good_p, -1.0), pressure(SURFACE + 2000.0 * RHO_G)]:
        w_depth.write(m)
        time.sleep(0.05)
    sent["depth"] = {"not_finite": 1, "bad_covariance": 1, "out_of_range": 1}
    for m in [twist(float("nan")), twist(10.0)]:
        w_dvl.write(m)
        time.sleep(0.05)
    sent["dvl"] = {"not_finite": 1, "out_of_range": 1}
    bad_to = time.time()
    good_for(2.0)
    print(json.dumps({"good": n_good, "bad_from": bad_from, "bad_to": bad_to, "sent": sent}))


if __name__ == "__main__":
    main()
