"""studyapp: side-by-side user studies of co-speech gesture models.

Subpackages mirror the architecture: ``motion`` (skeletal animation data), ``face`` (ARKit
blendshapes), ``audio`` (speech tracks and playback clocks), ``render`` (ModernGL viewer),
``study`` (designs, ordering, sessions, storage), ``ui`` (participant screens) and ``models``
(live ONNX gesture models). ``results_analysis`` is a separate package that reads only exported
results.
"""
from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
