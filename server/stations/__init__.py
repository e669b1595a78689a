"""The landing-base domain inside the server: live state, NTRIP caster, corrections routing."""
