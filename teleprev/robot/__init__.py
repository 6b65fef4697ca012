"""Robot descriptions: URDF parsing, kinematics, inverse kinematics and exact self-collision."""
