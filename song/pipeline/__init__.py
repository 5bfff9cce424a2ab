"""Per-scene synthesis stages (intents → crowd → motion → binding) and the run-level grading stage."""
