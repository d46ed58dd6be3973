"""The S1 colour particle filter (Barrera et al.): config, tracker, run job, report section and the papers'
experiments."""
