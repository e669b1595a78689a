"""Pure device logic of the landing base (no I/O): panels, lift, scale, weather, charger."""
