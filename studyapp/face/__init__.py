"""Facial animation: the 52 ARKit blendshapes, the canonical :class:`FaceAnimation` and its file formats."""
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_INDEX, ARKIT_NAMES, match_arkit_name
from studyapp.face.io import load_face, save_face_csv

__all__ = ["ARKIT_INDEX", "ARKIT_NAMES", "FaceAnimation", "load_face", "match_arkit_name", "save_face_csv"]
