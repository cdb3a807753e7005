"""Audio: WAV files as float arrays (:mod:`studyapp.audio.wav`), features and the playback clock.

Submodules are imported where needed so that loading a WAV never pulls in the sound-device stack.
"""
