"""Scoring tracks against ground truth: MOT metrics on the ground plane, box ground truth and convergence metrics."""
