"""The participant's experience: Dear ImGui screens over the 3D view, input, the environment check.

Entry points: :func:`studyapp.ui.app.run_window` (a participant in a window) and ``studyapp doctor``
(:mod:`studyapp.cli.doctor`, which uses :mod:`studyapp.ui.envcheck`).
The scripted participant that drives this same UI offscreen lives above it, in :mod:`studyapp.bots.ui_driver`.
"""
