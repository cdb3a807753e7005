"""Skeletal motion: data classes, BVH and array formats, rotations, kinematics, retargeting."""
from studyapp.motion.skeleton import Motion, Skeleton

__all__ = ["Motion", "Skeleton"]
