"""Live ONNX gesture models, run causally one frame at a time (contract in ``CONTRACT.md``).

* :mod:`studyapp.models.contract` -- input/output names, shapes and metadata a model must have;
* :mod:`studyapp.models.runner` -- :class:`~studyapp.models.runner.StreamingGestureModel` (onnxruntime, CPU);
* :mod:`studyapp.models.live` -- :func:`~studyapp.models.live.motion_for_stimulus` for study conditions, cached;
* :mod:`studyapp.models.reference` -- an untrained reference model built with ``onnx.helper``;
* :mod:`studyapp.models.encoder` -- a user's ONNX motion encoder for the Frechet Gesture Distance (``studyapp metrics``);
* ``studyapp generate`` lives in the shell, :mod:`studyapp.cli.models`.

Submodules are imported on use so that ``import studyapp`` does not load onnxruntime.
"""
