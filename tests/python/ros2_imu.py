"""Publishes sensor_msgs/msg/Imu on rt/imu/data with Cyclone DDS, as an
IMU driver on rmw_cyclonedds would: SECONDS of level readings at 20 Hz
(the vehicle heading 210°, i.e. facing a beacon whose axis heads 30°),
then BAD readings (a NaN quaternion, a quaternion of norm 1.2, in turn),
then good ones again for a second.

Usage: ros2_imu.py SECONDS BAD
Prints {"good": N, "bad": M} at the end.
"""

import json
import math
import sys
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic

from ros2_listener import Header, Imu, Quaternion, Time, Vector3


def imu(q):
    now = time.time()
    return Imu(
        header=Header(stamp=Time(sec=int(now), nanosec=int((now % 1) * 1e9)), frame_id="imu_link"),
        orientation=q,
        orientation_covariance=[0.0] * 9,
        angular_velocity=Vector3(0.0, 0.0, 0.0),
        angular_velocity_covariance=[0.0] * 9,
        linear_acceleration=Vector3(0.0, 0.0, 9.81),
        linear_acceleration_covariance=[0.0] * 9,
    )


def main():
    seconds, bad = float(sys.argv[1]), int(sys.argv[2])
    dp = DomainParticipant(0)
    w = DataWriter(dp, Topic(dp, "rt/imu/data", Imu))
    # Heading 210° (NED) is ENU yaw 90° − 210° = −120°, level.
    yaw = math.radians(90.0 - 210.0)
    good_q = Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    n_good = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        w.write(imu(good_q))
        n_good += 1
        time.sleep(0.05)
    for i in range(bad):
        q = Quaternion(float("nan"), 0.0, 0.0, 1.0) if i % 2 == 0 else Quaternion(0.0, 0.0, 0.0, 1.2)
        w.write(imu(q))
        time.sleep(0.05)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        w.write(imu(good_q))
        n_good += 1
        time.sleep(0.05)
    print(json.dumps({"good": n_good, "bad": bad}))


if __name__ == "__main__":
    main()
