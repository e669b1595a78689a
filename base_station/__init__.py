"""The landing-base daemon: PLC over Modbus TCP, safe motion, weather, scale, charging."""
