import math


def reward_function(params):
    all_wheels_on_track = params["all_wheels_on_track"]
    distance_from_center = params["distance_from_center"]
    track_width = params["track_width"]
    reward_lane = 1.0 if all_wheels_on_track and distance_from_center < 0.4 * track_width else 1e-3

    reward_avoid = 1.0
    if params.get("objects_location"):
        objects_location = params["objects_location"]
        _, next_object_index = params["closest_objects"]
        next_object_loc = objects_location[next_object_index]
        distance_closest_object = math.sqrt(
            (params["x"] - next_object_loc[0]) ** 2 + (params["y"] - next_object_loc[1]) ** 2
        )
        is_same_lane = (
            params["objects_left_of_center"][next_object_index] == params["is_left_of_center"]
        )
        if is_same_lane:
            if 0.5 <= distance_closest_object < 0.8:
                reward_avoid *= 0.5
            elif 0.3 <= distance_closest_object < 0.5:
                reward_avoid *= 0.2
            elif distance_closest_object < 0.3:
                reward_avoid = 1e-3
    return 1.0 * reward_lane + 4.0 * reward_avoid
