"""A trained policy driving a recording (`teleprev rollout`): its features, its runner, the LeRobot adapter."""
