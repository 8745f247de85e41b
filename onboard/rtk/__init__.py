"""Pure numerical GNSS core: ephemerides, satellite positions, single point and RTK positioning.

Imports the standard library, numpy and `onboard.gnsstime` only: no files, ports, clocks or parsers.
"""
