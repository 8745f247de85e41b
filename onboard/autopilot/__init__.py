"""The autopilot link (MAVLink): pure cores (GPS_RTCM_DATA reassembly, flight lifecycle, boot→GPS time) and the
recorder feature that runs the link (`onboard.autopilot.feature`)."""
