"""The S3 template tracker (Juza et al.): config, tracker, run job, offline track completion and report section."""
