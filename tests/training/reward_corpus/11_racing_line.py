import math


# A hand-made racing line: the waypoints, pulled 0.15 m toward the inside of every bend.
def racing_point(waypoints, i):
    n = len(waypoints) - 1
    a, b, c = waypoints[(i - 1) % n], waypoints[i % n], waypoints[(i + 1) % n]
    cross = (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])
    h = math.atan2(c[1] - a[1], c[0] - a[0])
    side = 0.15 if cross > 0 else -0.15 if cross < 0 else 0.0
    return b[0] - side * math.sin(h), b[1] + side * math.cos(h)


def reward_function(params):
    i = params["closest_waypoints"][1]
    rx, ry = racing_point(params["waypoints"], i)
    distance = math.hypot(params["x"] - rx, params["y"] - ry)
    return float(math.exp(-4 * distance))
