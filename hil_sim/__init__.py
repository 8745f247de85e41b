"""Hardware-in-the-loop simulator: the GNSS world (world.py), flight and camera models (flight.py, camera.py),
scenarios (scenario.py), and the receiver/base/autopilot emulators built on them.

Import the submodules directly (`from hil_sim.world import World`); this package file imports nothing so that
light users (e.g. the UBX encoder) do not pay for numpy/scipy physics at import.
"""
