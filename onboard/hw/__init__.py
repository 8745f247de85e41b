"""Hardware behind small interfaces: byte streams, edge sources, clocks (real and fake back-ends)."""
