"""What the apps share, below all of them: the Redis client for Pitlane's own keys, how times
and durations are written, the racer's time zone, and the rate limits. Imports no app."""
