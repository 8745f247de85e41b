"""Post-processing command lines over the cores: `convert` (RINEX 3.04), `rtk` (.pos), `check` (flight integrity)."""
