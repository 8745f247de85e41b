"""directgeo ground app: flight store, trajectory re-processing and the final adjustment."""
