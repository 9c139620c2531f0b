#!/usr/bin/python3
"""Publish N sensor_msgs/Image messages (rgb8, 3x2) on TOPIC with rospy, then exit.

    /usr/bin/python3 tools/ros/ros1_image_pub.py [TOPIC] [N] [HZ]

A ROS 1 peer for smoke tests; needs ROS_MASTER_URI and ROS_IP (or ROS_HOSTNAME) set.
"""
import sys

import rospy
from sensor_msgs.msg import Image

topic = sys.argv[1] if len(sys.argv) > 1 else "/camera/color/image_raw"
count = int(sys.argv[2]) if len(sys.argv) > 2 else 20
hz = float(sys.argv[3]) if len(sys.argv) > 3 else 10.0

rospy.init_node("voxpan_smoke_pub", anonymous=True, disable_signals=True)
pub = rospy.Publisher(topic, Image, queue_size=2)
msg = Image(height=2, width=3, encoding="rgb8", is_bigendian=0, step=9, data=bytes(range(18)))
msg.header.frame_id = "camera_color_optical_frame"
rate = rospy.Rate(hz)
for i in range(count):
    msg.header.seq = i
    msg.header.stamp = rospy.Time.now()
    pub.publish(msg)
    rate.sleep()
