"""Upload of recorded flights to the ground app: resumable, checksummed (`python -m onboard.upload`)."""
