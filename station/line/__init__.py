"""The calibration line's roles: the soak rack logs units at rest from power-on and stores the recordings; the rig
role finds them by serial and fits both recordings of one power-on together."""
