"""Motion evidence: the offline background model, motion masks (offline, MOG2, KNN), mask recall and the flood guard."""
