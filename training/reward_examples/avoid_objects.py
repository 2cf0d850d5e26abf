import math


def reward_function(params):
    """Avoid objects: stay on the track, and keep out of the lane of the next object ahead,
    the more so the closer it is."""
    all_wheels_on_track = params["all_wheels_on_track"]
    distance_from_center = params["distance_from_center"]
    track_width = params["track_width"]
    is_left_of_center = params["is_left_of_center"]

    # Staying on the track is worth 1.0, the centre lane more.
    reward_lane = 1e-3
    if all_wheels_on_track and (0.5 * track_width - distance_from_center) >= 0.05:
        reward_lane = 1.0

    reward_avoid = 1.0
    if params["objects_location"]:  # [] in a time trial
        _, next_object_index = params["closest_objects"]
        object_x, object_y = params["objects_location"][next_object_index]
        distance = math.hypot(params["x"] - object_x, params["y"] - object_y)
        same_lane = params["objects_left_of_center"][next_object_index] == is_left_of_center
        if same_lane:
            if 0.5 <= distance < 0.8:
                reward_avoid *= 0.5
            elif distance < 0.5:
                reward_avoid = 1e-3

    # Staying on the track matters, avoiding the object matters more.
    return float(1.0 * reward_lane + 4.0 * reward_avoid)
