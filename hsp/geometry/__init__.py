"""Pose algebra on 7-vectors ``[x, y, z, qx, qy, qz, qw]`` (scalar-last), world = table frame.

All conversions between poses, matrices, rotation vectors and yaw angles live here.
"""

from hsp.geometry.poses import (
    IDENTITY_POSE,
    apply_rotvec_delta,
    compose,
    inverse,
    normalize_quat,
    pose_from_matrix,
    pose_to_matrix,
    relative,
    rotation_angle_deg,
    rotvec_delta,
    slerp,
    transform_points,
    yaw_of,
)

__all__ = [
    "IDENTITY_POSE",
    "apply_rotvec_delta",
    "compose",
    "inverse",
    "normalize_quat",
    "pose_from_matrix",
    "pose_to_matrix",
    "relative",
    "rotation_angle_deg",
    "rotvec_delta",
    "slerp",
    "transform_points",
    "yaw_of",
]
