"""Simulated downward camera: the landing pad as rendered, the renderer and the frame server."""
