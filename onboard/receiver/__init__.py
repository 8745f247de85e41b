"""The receiver boundary: framing, decoding (the only pyubx2/pyrtcm users) and configuration."""
