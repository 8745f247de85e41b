"""The recorder daemon (`python -m onboard run`): composition root, settings, status snapshot, sd_notify, and the
feature interface through which real-time RTK, the base station and the autopilot link extend it."""
