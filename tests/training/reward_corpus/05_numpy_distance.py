import numpy as np


def reward_function(params):
    # Distance to the centre line, recomputed with numpy from the two closest waypoints.
    waypoints = np.array(params["waypoints"])
    behind, ahead = params["closest_waypoints"]
    a, b = waypoints[behind], waypoints[ahead]
    p = np.array([params["x"], params["y"]])
    t = np.clip(np.dot(p - a, b - a) / max(np.dot(b - a, b - a), 1e-9), 0.0, 1.0)
    distance = np.linalg.norm(p - (a + t * (b - a)))
    half = params["track_width"] / 2
    return float(max(1e-3, 1.0 - (distance / half) ** 2))
