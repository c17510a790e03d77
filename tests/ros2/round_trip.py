"""A third-party ROS 2 round trip with iwsim's ROS 2 bridge: a node made with the official Zenoh
binding and rosbags only (rmw_node.py) reads /map and /NAME/tf_static (transient-local),
/clock, /NAME/odom and /NAME/scan, decoding every message with rosbags, and answers every
/clock with the same cmd_vel (V m/s, W rad/s), encoded by rosbags.

    python round_trip.py ENDPOINT NAME V W [ANSWERS]

With ANSWERS it answers only that many clocks and then falls silent, its publisher still there:
a controller that hangs, which the base driver's zero-velocity timeout must stop.

It prints what it saw, one `key value...` per line, and ends when /clock has been quiet for
3 s after the run started (the hub ended it).
"""

import math
import sys
import time

import rmw_node as rmw

endpoint, name, v, w = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
answers = int(sys.argv[5]) if len(sys.argv) > 5 else None
session = rmw.open_session(endpoint)
node = rmw.Node(session, 0, "/", "round_trip")
ns = f"/{name}"

deadline = time.monotonic() + 60
maps, statics = [], []
while time.monotonic() < deadline and not (maps and statics):
    maps = maps or node.latched("/map", "nav_msgs/msg/OccupancyGrid")
    statics = statics or node.latched(f"{ns}/tf_static", "tf2_msgs/msg/TFMessage")
if not (maps and statics):
    sys.exit(f"no /map ({len(maps)}) or {ns}/tf_static ({len(statics)}) from the bridge's cache")
grid = maps[0]
print("map", grid.info.width, grid.info.height, f"{grid.info.resolution:.3f}", grid.header.frame_id)
print("map_occupied", int((grid.data == 100).sum()), "free", int((grid.data == 0).sum()))
frames = sorted(f"{t.header.frame_id}>{t.child_frame_id}" for t in statics[0].transforms)
print("tf_static", " ".join(frames))

clock, odom, scan = rmw.Latest(), rmw.Latest(), rmw.Latest()
sent = [0]
last_answered = [None]
cmd = None


def on_clock(msg, ok):
    clock(msg, ok)
    if cmd is None or (answers is not None and sent[0] >= answers):
        return
    # A use_sim_time controller: one command per tick of the simulation's clock.
    cmd.put(rmw.twist(v, w))
    sent[0] += 1
    last_answered[0] = f"{msg.clock.sec}.{msg.clock.nanosec:09d}"


node.subscribe("/clock", "rosgraph_msgs/msg/Clock", on_clock, rmw.QOS_SENSOR)
node.subscribe(f"{ns}/odom", "nav_msgs/msg/Odometry", odom)
node.subscribe(f"{ns}/scan", "sensor_msgs/msg/LaserScan", scan, rmw.QOS_SENSOR)
# The publisher last: its token tells the bridge the chair has a controller, and a lock-step
# run starts, so every subscription must be in place first.
cmd = node.publisher(f"{ns}/cmd_vel", "geometry_msgs/msg/Twist")
# Junk first, which the bridge must count and drop: three bytes that are no Twist.
cmd.pub.put(b"\x00\x01\x00")
if answers is None:
    cmd.put(rmw.twist(v, w))

start = time.monotonic()
while time.monotonic() - start < 300:
    with clock.lock:
        count = clock.count
        clock.lock.wait(3.0)
        if clock.count == count and count > 0:
            break

c, o, s = clock.msg, odom.msg, scan.msg
if c is None or o is None or s is None:
    sys.exit(f"nothing came: clock {clock.count} odom {odom.count} scan {scan.count}")
print("clock", clock.count, f"{c.clock.sec}.{c.clock.nanosec:09d}")
print("odom", odom.count, o.header.frame_id, o.child_frame_id)
p, q = o.pose.pose.position, o.pose.pose.orientation
print("odom_pose", f"{p.x:.4f}", f"{p.y:.4f}", f"{2 * math.atan2(q.z, q.w):.4f}")
print("odom_twist", f"{o.twist.twist.linear.x:.4f}", f"{o.twist.twist.angular.z:.4f}")
print("scan", scan.count, s.header.frame_id, len(s.ranges), f"{s.angle_increment:.5f}")
print("bad_attachments", clock.bad_attachments + odom.bad_attachments + scan.bad_attachments)
print("cmd_vel", sent[0], last_answered[0])
session.close()
