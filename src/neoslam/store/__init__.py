"""A map that persists: one SQLite file written as the run goes, loaded by later sessions."""
