"""The `aerobase` console script: one entry point that dispatches to each deployable."""
