import math


def reward_function(params):
    """Go fast when the track ahead is straight, slow when it bends."""
    if params["is_offtrack"] or not params["all_wheels_on_track"]:
        return 1e-3
    waypoints = params["waypoints"]
    i = params["closest_waypoints"][1]
    ahead = [waypoints[(i + k) % len(waypoints)] for k in range(0, 8)]
    turn = 0.0
    for a, b, c in zip(ahead, ahead[1:], ahead[2:]):
        h1 = math.atan2(b[1] - a[1], b[0] - a[0])
        h2 = math.atan2(c[1] - b[1], c[0] - b[0])
        d = math.degrees(h2 - h1)
        d = (d + 180) % 360 - 180
        turn += abs(d)
    speed = params["speed"]
    if turn < 15:
        return float(0.5 + speed / 4.0)
    return float(1.0 - min(speed, 4.0) / 8.0)
