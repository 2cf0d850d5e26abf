def reward_function(params):
    distance_from_center = params["distance_from_center"]
    track_width = params["track_width"]
    steering = abs(params["steering_angle"])
    speed = params["speed"]

    reward = 1.0 - (distance_from_center / (track_width / 2)) ** 0.5
    reward = max(reward, 1e-3)

    # Penalise steering hard, and reward speed a little.
    if steering > 20:
        reward *= 0.7
    reward += 0.1 * speed

    return float(reward)
