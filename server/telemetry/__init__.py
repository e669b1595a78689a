"""Telemetry series and asset events: storage behind one interface, SQL or InfluxDB."""
