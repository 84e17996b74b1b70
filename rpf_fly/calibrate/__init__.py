"""``rpf-fly calibrate``: fit a drone's closed-loop response from a flight log or a trace, and write it as a vehicle
profile that a dry run flies (docs/dynamics.md, "Calibrating a vehicle profile").

- `record`: one drone's setpoint stream and measured positions, from an MCAP log or a trace JSON;
- `replay`: that stream flown on the offline firmware model with chosen gains;
- `fit`: the gains (and the mocap's latency and noise) under which the replay flies where the drone flew;
- `profile`: the profile file, written and read (the mission loader reads ``dry_run.vehicle`` with it).
"""
