"""The participant's experience: Dear ImGui screens over the 3D view, input, scripted participant, doctor.

Entry points: :func:`studyapp.ui.app.run_window` (a participant in a window),
:func:`studyapp.ui.app.run_offscreen_bot` (a scripted participant through the same UI, offscreen) and
``studyapp doctor`` (:mod:`studyapp.cli.doctor`, which uses :mod:`studyapp.ui.envcheck`).
"""
