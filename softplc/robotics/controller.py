"""Local control: differential-drive kinematics and a pure-pursuit path follower.

The follower turns a path of waypoints into (v, w) commands within the robot's speed limits:
it rotates in place when the path is far off its heading, otherwise steers along the arc
through a look-ahead point, slowing down for tight turns and at the end of the path.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from softplc.robotics.robots import Pose


@dataclass(frozen=True)
class SpeedLimits:
    """Bounds of a robot's commands: m/s, rad/s, and how fast it may speed up."""

    linear: float = 0.2
    angular: float = 0.4
    linear_acceleration: float = 0.5  # m/s²
    angular_acceleration: float = 1.5  # rad/s²


def wrap_angle(angle: float) -> float:
    """The same angle in (-pi, pi]."""
    wrapped = math.fmod(angle + math.pi, 2.0 * math.pi)
    if wrapped <= 0.0:
        wrapped += 2.0 * math.pi
    return wrapped - math.pi


def integrate(pose: Pose, v: float, w: float, dt: float) -> Pose:
    """Pose after driving at (v, w) for dt: the exact arc of a differential-drive robot."""
    heading = pose.heading
    if abs(w) < 1e-9:
        return Pose(pose.x + v * dt * math.cos(heading), pose.y + v * dt * math.sin(heading), heading)
    new_heading = heading + w * dt
    radius = v / w
    return Pose(
        pose.x + radius * (math.sin(new_heading) - math.sin(heading)),
        pose.y - radius * (math.cos(new_heading) - math.cos(heading)),
        wrap_angle(new_heading),
    )


class PurePursuit:
    """Pure pursuit along a polyline, with rotate-in-place for large heading errors."""

    def __init__(
        self,
        lookahead: float = 0.35,
        rotate_threshold: float = math.radians(40),
        slowdown_distance: float = 0.5,
        heading_gain: float = 2.0,
    ) -> None:
        self.lookahead = lookahead
        self.rotate_threshold = rotate_threshold
        self.slowdown_distance = slowdown_distance
        self.heading_gain = heading_gain

    def progress(self, pose: Pose, path: Sequence[tuple[float, float]], segment: int) -> int:
        """Index of the path segment the robot is on now (never moves backwards)."""
        last = len(path) - 2
        while segment < last:
            (ax, ay), (bx, by) = path[segment], path[segment + 1]
            dx, dy = bx - ax, by - ay
            length2 = dx * dx + dy * dy
            t = ((pose.x - ax) * dx + (pose.y - ay) * dy) / length2 if length2 > 0 else 1.0
            # Past the segment's end, or already closer to the next waypoint than the look-ahead.
            if t >= 1.0 or math.hypot(bx - pose.x, by - pose.y) < self.lookahead * 0.5:
                segment += 1
            else:
                break
        return segment

    def target(self, pose: Pose, path: Sequence[tuple[float, float]], segment: int) -> tuple[float, float]:
        """The look-ahead point: the first point of the path ahead at look-ahead distance."""
        for index in range(segment, len(path) - 1):
            (ax, ay), (bx, by) = path[index], path[index + 1]
            point = _circle_exit(pose.x, pose.y, self.lookahead, ax, ay, bx, by)
            if point is not None:
                return point
        return path[-1]

    def command(
        self,
        pose: Pose,
        path: Sequence[tuple[float, float]],
        segment: int,
        limits: SpeedLimits,
        current: tuple[float, float] = (0.0, 0.0),
        dt: float = 0.1,
        *,
        careful: bool = False,
    ) -> tuple[float, float]:
        """(v, w) toward the path within `limits`; (0, 0) once at the path's end.

        `careful` (near a wall): steer at the next waypoint itself instead of a look-ahead
        point, and turn on the spot for smaller heading errors, so no corner is cut.
        """
        if careful:
            tx, ty = path[min(segment + 1, len(path) - 1)]
        else:
            tx, ty = self.target(pose, path, segment)
        rotate_threshold = self.rotate_threshold / 3 if careful else self.rotate_threshold
        end_x, end_y = path[-1]
        remaining = math.hypot(end_x - pose.x, end_y - pose.y)
        alpha = wrap_angle(math.atan2(ty - pose.y, tx - pose.x) - pose.heading)
        if abs(alpha) > rotate_threshold:
            v = 0.0
            w = math.copysign(min(limits.angular, self.heading_gain * abs(alpha)), alpha)
        else:
            distance = max(math.hypot(tx - pose.x, ty - pose.y), 1e-6)
            curvature = 2.0 * math.sin(alpha) / distance
            v = limits.linear * min(1.0, max(0.15, remaining / self.slowdown_distance))
            # Slow down in proportion to the heading error: arcs stay tight and inside the lane.
            v *= max(0.2, 1.0 - abs(alpha) / rotate_threshold * 0.7)
            w = v * curvature
            if abs(w) > limits.angular:
                v *= limits.angular / abs(w)
                w = math.copysign(limits.angular, w)
        return limit_acceleration((v, w), current, limits, dt)


def limit_acceleration(command: tuple[float, float], current: tuple[float, float], limits: SpeedLimits, dt: float) -> tuple[float, float]:
    """Clamp a command to the speed limits and to how fast the robot may speed up (not brake)."""
    v, w = command
    v0, w0 = current
    v = max(-limits.linear, min(limits.linear, v))
    w = max(-limits.angular, min(limits.angular, w))
    if abs(v) > abs(v0):
        step = limits.linear_acceleration * dt
        v = max(v0 - step, min(v0 + step, v))
    if abs(w) > abs(w0):
        step = limits.angular_acceleration * dt
        w = max(w0 - step, min(w0 + step, w))
    return v, w


def _circle_exit(cx: float, cy: float, r: float, ax: float, ay: float, bx: float, by: float) -> tuple[float, float] | None:
    """The point where segment a→b leaves the circle (c, r), or None if it does not."""
    dx, dy = bx - ax, by - ay
    fx, fy = ax - cx, ay - cy
    a = dx * dx + dy * dy
    if a == 0:
        return None
    b = 2 * (fx * dx + fy * dy)
    c = fx * fx + fy * fy - r * r
    disc = b * b - 4 * a * c
    if disc < 0:
        return None
    t = (-b + math.sqrt(disc)) / (2 * a)
    if 0.0 <= t <= 1.0:
        return ax + t * dx, ay + t * dy
    return None
