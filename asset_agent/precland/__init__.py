"""Precision landing: pad detection, pose estimation, fusion, fault injection and landing control.

Pure computation (detect, pose, kalman, fusion, faults, control, retry) plus one thin loop
(`loop.PrecisionLandingLoop`) and the sensor transports (`transport`). Nothing here imports sim/.
"""
