"""One module per participant screen; each has ``draw(app)`` and reads/writes state through the app."""
