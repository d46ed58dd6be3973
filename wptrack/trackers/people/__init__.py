"""The S2 multi-camera people tracker: config, tracker, run job and report section."""
