"""directgeo onboard: receiver link, raw journal, camera time marks and the RTK engine."""
