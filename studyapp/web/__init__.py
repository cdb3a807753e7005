"""The browser study server (``studyapp serve``): the desktop's study session, in a browser, for online studies.

One path: the server drives the same :class:`~studyapp.study.session.Session` state machine and the same results
database as the desktop app; the browser is just another front end. Participants watch pre-rendered trial videos
(:mod:`studyapp.web.media`) under opaque per-participant addresses (:mod:`studyapp.web.tokens`).

Modules: :mod:`.flow` (the participant's pages as session states, assignment, abandonment), :mod:`.app` (HTTP
routes), :mod:`.security` (headers, rate limits, request checks), :mod:`.dashboard` (the experimenter's side),
:mod:`.database` (opening the results database from a ``--db`` URL), :mod:`.uploads` (desktop bundle
participants' answers, ``POST /upload``), ``assets/`` (the pages' script and style).
"""
