"""The simulated multirotor autopilot (ArduPilot Copter over MAVLink 2) and its pure dynamics.

Entry points: `run_vehicle(...)` (async context manager serving one vehicle on free ports),
`VehicleServer`, `Copter`, `CopterConfig`, `Base` (the landing-base protocol), `OpenPad`
(the stand-in base) and `vehicle_router(server)` (the world's HTTP control interface).
"""
