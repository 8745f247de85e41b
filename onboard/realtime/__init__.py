"""Real-time RTK in the recorder: base corrections (radio, TCP, NTRIP) in, one solution per rover epoch out."""
