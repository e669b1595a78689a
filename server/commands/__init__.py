"""Commands to assets: queued, delivered to whichever process holds the socket, tracked to the end."""
