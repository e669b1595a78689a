"""Precision landing, all of it: pad detection, pose estimation, fusion, fault injection, control.

One module per job; the first four stack, each wrapping the next:
- `supervisor`: the daemon's part — watches the autopilot, starts the loop while it lands below
  the activation height, feeds it the sensors and sends its LANDING_TARGETs; the fault command.
- `loop`: the one thin asyncio loop — detection in a worker thread, the control step on a timer.
- `pipeline`: no I/O — detections, IR and vehicle states through faults, fusion and the Kalman
  filter to one control step (`Tick`); the evaluation (bench/precland_eval.py) drives it directly.
- `sequence`: the companion-mode landing sequence with its cautious retries (a state machine).
- around the autopilot's own LAND, in the daemon: `takeover` (the search and its fallback, in
  GUIDED), `guard` (a pad lost too high), `resume` (an agent restarted in the middle of either),
  `readiness` (the PLND parameters), `report` (what a landing did, for the `landed` event).
- pure computation under them: `detect`, `measure`, `geometry`, `fusion`, `kalman`, `faults`,
  `control`; `clock` (the sensors' clock), `transport` (camera and IR receivers), `config`.
Nothing here imports sim/.
"""
