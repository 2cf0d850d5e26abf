def reward_function(params):
    """Reward progress made per step, to encourage a fast lap."""
    steps = params["steps"]
    progress = params["progress"]
    if params["is_offtrack"]:
        return 1e-3
    if steps <= 0:
        return 1.0
    reward = progress / steps * 10
    if progress == 100:
        reward += 100
    return float(reward)
