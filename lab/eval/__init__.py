"""Evaluation: error rates, the RGB baseline, bandwidth accounting, suites and reports."""
