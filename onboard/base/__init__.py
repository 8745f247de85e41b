"""Base-station mode (`python -m onboard base`): record the static receiver and send RTCM3 over the radio."""
