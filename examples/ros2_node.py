"""A ROS 2 node around sbmpc's controller (docs/robot.md, section 8).

An example, outside the package and its tests: ``rclpy`` comes with a ROS 2 install, not
from PyPI. The node only moves messages; the logic is :class:`sbmpc.Controller`'s, which
the tests cover.

    source /opt/ros/humble/setup.bash
    pip install -e '.[ros]'
    python examples/ros2_node.py --ros-args -p scenario:=field.yaml -p cost:=energy \\
        -p cmd_vel:=/husky_velocity_controller/cmd_vel_unstamped

Subscribes: ``odom`` (nav_msgs/Odometry: the pose, in the map's frame), ``joint_states``
(sensor_msgs/JointState: wheel speeds and efforts, the joints of each side named by
``left_joints``/``right_joints``, else those with 'left'/'right' in their names),
``battery`` (sensor_msgs/BatteryState, optional) and ``grid_map`` (grid_map_msgs/GridMap,
optional: a new map replaces the scenario's and restarts the controller).
Publishes: ``cmd_vel`` (geometry_msgs/Twist), ``plan`` (nav_msgs/Path, each new plan),
``status`` (std_msgs/String). Every topic name is a parameter; ``period`` is the control
period [s], ``horizon`` the look-ahead [s] (0: the scenario's), ``frame`` the plans' frame id.
"""
from __future__ import annotations

import math
import threading

import rclpy
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry, Path
from rclpy.node import Node
from sensor_msgs.msg import BatteryState, JointState
from std_msgs.msg import String

import sbmpc
from sbmpc.errors import InputError


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


class SbmpcNode(Node):
    def __init__(self):
        super().__init__("sbmpc")
        p = {name: self.declare_parameter(name, default).value for name, default in (
            ("scenario", ""), ("cost", ""), ("period", 0.1), ("horizon", 0.0), ("frame", "map"),
            ("odom", "/odom"), ("joint_states", "/joint_states"), ("battery", "/battery_state"),
            ("grid_map", ""), ("grid_map_layer", "elevation"), ("cmd_vel", "/cmd_vel"), ("plan", "/sbmpc/plan"),
            ("status", "/sbmpc/status"), ("left_joints", [""]), ("right_joints", [""]))}
        if not p["scenario"]:
            raise SystemExit("sbmpc node: parameter 'scenario': expected a scenario YAML file, found none")
        self.p = p
        self.world = sbmpc.load_world(p["scenario"])
        self.ctrl = self._controller(self.world)
        self.pose = self.wheels = self.efforts = self.voltage = None
        self.names = None
        self.paths_sent = 0
        self.cmd_pub = self.create_publisher(Twist, p["cmd_vel"], 10)
        self.plan_pub = self.create_publisher(Path, p["plan"], 1)
        self.status_pub = self.create_publisher(String, p["status"], 10)
        self.create_subscription(Odometry, p["odom"], self.on_odom, 10)
        self.create_subscription(JointState, p["joint_states"], self.on_joints, 10)
        self.create_subscription(BatteryState, p["battery"], self.on_battery, 10)
        if p["grid_map"]:
            from grid_map_msgs.msg import GridMap
            self.create_subscription(GridMap, p["grid_map"], self.on_grid_map, 1)
        self.create_timer(float(p["period"]), self.on_tick)

    def _controller(self, world):
        # horizon 0: the scenario's planner.horizon_s (10 s where it has none)
        return sbmpc.Controller(world, self.p["cost"] or None, period_s=float(self.p["period"]),
                                horizon_s=float(self.p["horizon"]) or None, keep_paths=True)

    # ---- measurements: the latest of each ------------------------------------------
    def on_odom(self, msg: Odometry):
        q = msg.pose.pose.orientation
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y, _yaw(q))

    def on_joints(self, msg: JointState):
        if self.names != list(msg.name):
            self.names = list(msg.name)
            left = [n for n in self.p["left_joints"] if n] or [n for n in self.names if "left" in n]
            right = [n for n in self.p["right_joints"] if n] or [n for n in self.names if "right" in n]
            missing = [n for n in left + right if n not in self.names]
            if missing:
                self.get_logger().error(f"joint_states: expected the joints {', '.join(missing)}, found "
                                        f"{', '.join(self.names)}; wheel speeds left out")
            self.sides = ([self.names.index(n) for n in left if n in self.names],
                          [self.names.index(n) for n in right if n in self.names])
        L, R = self.sides
        if len(msg.velocity) == len(self.names) and L and R:
            self.wheels = (sum(msg.velocity[i] for i in L) / len(L), sum(msg.velocity[i] for i in R) / len(R))
        if len(msg.effort) == len(self.names) and L and R:
            self.efforts = (sum(msg.effort[i] for i in L), sum(msg.effort[i] for i in R))

    def on_battery(self, msg: BatteryState):
        self.voltage = float(msg.voltage)

    def on_grid_map(self, msg):
        from maps.gridmap import gridmap_heights
        try:
            H, res, origin = gridmap_heights(msg, self.p["grid_map_layer"], "wall", "grid_map", self.p["grid_map"],
                                             InputError)
            world = sbmpc.load_world(self.world.scenario, heights=H, resolution=res, origin=origin)
        except InputError as exc:
            self.get_logger().error(f"grid map refused: {exc}")
            return
        self.cmd_pub.publish(Twist())             # at rest while the controller starts again on the new map
        old, self.ctrl = self.ctrl, None
        threading.Thread(target=old.close, daemon=True).start()   # never wait here on a plan being made
        self.world, self.ctrl, self.paths_sent = world, self._controller(world), 0
        self.get_logger().info("new grid map: the controller starts again on it")

    # ---- the loop -----------------------------------------------------------------------
    def on_tick(self):
        if self.pose is None or self.ctrl is None:
            return                                # no pose yet, or a controller starting: nothing new to command
        t = self.get_clock().now().nanoseconds * 1e-9
        kw = {}
        if self.wheels is not None:
            kw.update(wl=self.wheels[0], wr=self.wheels[1])
        if self.efforts is not None:
            kw.update(tau_l=self.efforts[0], tau_r=self.efforts[1])
        if self.voltage is not None and math.isfinite(self.voltage):
            kw.update(voltage=self.voltage)
        try:
            cmd = self.ctrl.step(t, sbmpc.Measurement(*self.pose, **kw))
        except InputError as exc:                 # a bad measurement: stop, say why, go on at the next
            self.get_logger().warn(str(exc))
            self.cmd_pub.publish(Twist())
            return
        tw = Twist()
        tw.linear.x, tw.angular.z = cmd.v, cmd.omega
        self.cmd_pub.publish(tw)
        self.status_pub.publish(String(data=cmd.status if not cmd.reason else f"{cmd.status}: {cmd.reason}"))
        while self.paths_sent < len(self.ctrl.paths):
            _, path = self.ctrl.paths[self.paths_sent]
            self.paths_sent += 1
            out = Path()
            out.header.frame_id = self.p["frame"]
            out.header.stamp = self.get_clock().now().to_msg()
            for x, y, z, yaw in zip(path["x"], path["y"], path["z"], path["yaw"]):
                ps = PoseStamped()
                ps.header = out.header
                ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = float(x), float(y), float(z)
                ps.pose.orientation.z, ps.pose.orientation.w = math.sin(0.5 * yaw), math.cos(0.5 * yaw)
                out.poses.append(ps)
            self.plan_pub.publish(out)

    def destroy_node(self):
        self.ctrl.close()
        super().destroy_node()


def main():
    rclpy.init()
    node = SbmpcNode()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.cmd_pub.publish(Twist())             # leave the robot at rest
        node.destroy_node()
        rclpy.shutdown()


if __name__ == "__main__":
    main()
