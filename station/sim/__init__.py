"""Simulated peers and the physics they run: rig kinematics and IMU sensor model."""
