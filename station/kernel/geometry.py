"""Rig geometry: how the rig's three axes orient the sensor and what it then feels.

The rig is a two-axis tumble gimbal (roll about the sensor's x, pitch about y)
mounted on a rate table spinning about the world vertical (yaw). The sensor frame
is rotated into the world (x east, y north, z up) by ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
At rest the specific force points up: ``f_world = (0, 0, g)``.
All angles in rad, rates in rad/s, accelerations in rad/s^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# The six gravity poses: which nominal sensor axis points up -> (roll, pitch) in deg.
POSE_ANGLES_DEG: dict[str, tuple[float, float]] = {
    "+z": (0.0, 0.0),
    "-z": (180.0, 0.0),
    "+x": (0.0, -90.0),
    "-x": (0.0, 90.0),
    "+y": (90.0, 0.0),
    "-y": (-90.0, 0.0),
}

AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


def up_vector(pose: str) -> np.ndarray:
    """Unit vector (sensor frame) of the axis pointing up in ``pose`` ('+x', '-z', ...)."""
    v = np.zeros(3)
    v[AXIS_INDEX[pose[1]]] = 1.0 if pose[0] == "+" else -1.0
    return v


def rotation_matrices(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Sensor-to-world rotations ``Rz(yaw) Ry(pitch) Rx(roll)``, shape (n, 3, 3)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    r = np.empty((*np.shape(roll), 3, 3))
    r[..., 0, 0] = cy * cp
    r[..., 0, 1] = cy * sp * sr - sy * cr
    r[..., 0, 2] = cy * sp * cr + sy * sr
    r[..., 1, 0] = sy * cp
    r[..., 1, 1] = sy * sp * sr + cy * cr
    r[..., 1, 2] = sy * sp * cr - cy * sr
    r[..., 2, 0] = -sp
    r[..., 2, 1] = cp * sr
    r[..., 2, 2] = cp * cr
    return r


def rotation_vector_matrix(phi: np.ndarray) -> np.ndarray:
    """Rotation matrix ``exp([phi]x)`` (3, 3) of the rotation vector ``phi`` (rad), (3,) (Rodrigues)."""
    phi = np.asarray(phi, dtype=float)
    angle = float(np.linalg.norm(phi))
    k = np.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]])
    out: np.ndarray
    if angle < 1e-12:
        out = np.eye(3) + k
    else:
        out = np.eye(3) + (np.sin(angle) / angle) * k + ((1.0 - np.cos(angle)) / angle**2) * (k @ k)
    return out


@dataclass(frozen=True)
class Kinematics:
    """What the sensor frame does at each sample time.

    Attributes:
        t_s: times (s), shape (n,).
        rotation: sensor-to-world rotation matrices, shape (n, 3, 3).
        omega_radps: angular rate of the sensor in the sensor frame, shape (n, 3).
        alpha_radps2: angular acceleration in the sensor frame, shape (n, 3).
    """

    t_s: np.ndarray
    rotation: np.ndarray
    omega_radps: np.ndarray
    alpha_radps2: np.ndarray

    def up_in_sensor(self) -> np.ndarray:
        """World 'up' expressed in the sensor frame, shape (n, 3)."""
        return self.rotation[:, 2, :]

    def specific_force(self, gravity_mps2: float) -> np.ndarray:
        """Specific force (m/s^2, sensor frame) of a point at the rotation centre."""
        return gravity_mps2 * self.up_in_sensor()


def kinematics_from_angles(
    t_s: np.ndarray,
    angle: np.ndarray,
    rate: np.ndarray,
    accel: np.ndarray,
) -> Kinematics:
    """Sensor kinematics from the rig's axis states.

    ``angle``, ``rate`` and ``accel`` have shape (n, 3), columns (roll, pitch, yaw),
    in rad, rad/s, rad/s^2. Body rates are the ZYX Euler-rate relation; the angular
    acceleration is its exact time derivative.
    """
    phi, th = angle[:, 0], angle[:, 1]
    dphi, dth, dpsi = rate[:, 0], rate[:, 1], rate[:, 2]
    ddphi, ddth, ddpsi = accel[:, 0], accel[:, 1], accel[:, 2]
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(th), np.sin(th)
    omega = np.empty((len(t_s), 3))
    omega[:, 0] = dphi - dpsi * st
    omega[:, 1] = dth * cf + dpsi * sf * ct
    omega[:, 2] = -dth * sf + dpsi * cf * ct
    alpha = np.empty((len(t_s), 3))
    alpha[:, 0] = ddphi - ddpsi * st - dpsi * ct * dth
    alpha[:, 1] = ddth * cf - dth * sf * dphi + ddpsi * sf * ct + dpsi * (cf * dphi * ct - sf * st * dth)
    alpha[:, 2] = -ddth * sf - dth * cf * dphi + ddpsi * cf * ct + dpsi * (-sf * dphi * ct - cf * st * dth)
    return Kinematics(np.asarray(t_s, dtype=float), rotation_matrices(phi, th, angle[:, 2]), omega, alpha)
