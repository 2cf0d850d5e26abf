import numpy as np
from scipy.interpolate import splprep, splev


def reward_function(params):
    # Smooth the next waypoints with a spline and compare the car's heading with the curve's.
    waypoints = params["waypoints"]
    i = params["closest_waypoints"][0]
    pts = np.array([waypoints[(i + k) % (len(waypoints) - 1)] for k in range(6)])
    tck, _ = splprep([pts[:, 0], pts[:, 1]], s=0.01, k=3)
    dx, dy = splev(0.2, tck, der=1)
    curve_heading = np.degrees(np.arctan2(dy, dx))
    diff = abs((curve_heading - params["heading"] + 180) % 360 - 180)
    return float(max(0.01, 1.0 - diff / 90.0))
