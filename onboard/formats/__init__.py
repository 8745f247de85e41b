"""File formats read and written by the shells (RINEX, RTKLIB .pos, CSV). Parsing only, no numerics."""
