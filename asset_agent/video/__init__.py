"""The drone's live video: a camera source encoded once on board and published with WHIP."""
