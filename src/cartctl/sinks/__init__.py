"""Sinks: where the loop's per-tick values go (CSV trace, Rerun recording/viewer, summary)."""
