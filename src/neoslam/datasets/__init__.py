"""One reader per data source; each yields `Frame`s and, apart, the ground truth that only evaluation reads."""
