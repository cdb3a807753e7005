"""Skeletal motion: data classes, BVH and array formats, rotations, kinematics, retargeting."""
from studyapp.motion.skeleton import Motion, Skeleton
from studyapp.motion.beat import BEAT_JOINTS, BEAT_UPPER_BODY, beat_motion_from_upper_body, beat_skeleton
from studyapp.motion.bvh import BvhData, read_bvh, read_bvh_channels, write_bvh
from studyapp.motion.fk import figure_height, forward_kinematics, global_transforms, joint_positions
from studyapp.motion.io import load_motion, summarize_motion
from studyapp.motion.resample import check_duration, resample, trim
from studyapp.motion.arrays import load_rotation_array, save_motion_npz
from studyapp.motion.retarget import detect_name_map, retarget

__all__ = [
    "Motion",
    "Skeleton",
    "BEAT_JOINTS",
    "BEAT_UPPER_BODY",
    "beat_motion_from_upper_body",
    "beat_skeleton",
    "BvhData",
    "read_bvh",
    "read_bvh_channels",
    "write_bvh",
    "figure_height",
    "forward_kinematics",
    "global_transforms",
    "joint_positions",
    "load_motion",
    "summarize_motion",
    "check_duration",
    "resample",
    "trim",
    "load_rotation_array",
    "save_motion_npz",
    "detect_name_map",
    "retarget",
]
