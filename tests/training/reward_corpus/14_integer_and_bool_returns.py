def reward_function(params):
    # Returns an int or a bool: DeepRacer accepts both, and so do we.
    if params["is_offtrack"]:
        return 0
    return params["all_wheels_on_track"]
