"""Rotation matrices to quaternions (the form the review app and the recorders draw)."""

from __future__ import annotations

import numpy as np


def rotations_to_wxyz(rot: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotation matrices -> ``(..., 4)`` unit quaternions (w, x, y, z), w >= 0
    (pinocchio's conversion; scipy.spatial would cost more to import than to run)."""
    import pinocchio as pin

    flat = rot.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4))
    for k in range(flat.shape[0]):
        x, y, z, w = pin.Quaternion(flat[k]).coeffs()
        out[k] = (w, x, y, z) if w >= 0 else (-w, -x, -y, -z)
    return out.reshape(rot.shape[:-2] + (4,))
