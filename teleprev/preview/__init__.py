"""The terminal preview: what the robot would do, what it does, corrections, rates, and the keys."""
