"""Assets (UAVs and landing bases) and their encrypted credential files."""
