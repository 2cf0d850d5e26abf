from shapely.geometry import Point, Polygon


def reward_function(params):
    # Is the car inside a corridor 60% of the track's width around the centre line?
    waypoints = params["waypoints"]
    behind, ahead = params["closest_waypoints"]
    (x1, y1), (x2, y2) = waypoints[behind], waypoints[ahead]
    corridor = Polygon([(x1, y1), (x2, y2), (x2, y2), (x1, y1)]).buffer(0.3 * params["track_width"])
    inside = corridor.contains(Point(params["x"], params["y"]))
    return 1.0 if inside else 0.2
