"""The control API: verbs, the control stage, the WebSocket and OSC servers and their pages (``run --web``)."""
