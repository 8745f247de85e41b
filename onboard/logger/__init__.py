"""Raw journal: segments, sidecar index, manifest, event log and their torn-tail tolerant readers."""
