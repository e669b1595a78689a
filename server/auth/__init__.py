"""Login, sessions (one live session per account), rate limits and the caller's identity."""
