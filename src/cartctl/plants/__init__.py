"""Plants: what experiments and the loop drive, one tick at a time (docs/plants.md)."""
