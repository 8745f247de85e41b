"""Pure numpy/scipy core of the final adjustment (similarity, lever arm, shutter delay, GCPs)."""
